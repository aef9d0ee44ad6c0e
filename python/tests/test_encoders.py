"""Image encoders (issue 31): modesuite's DINOv2 ViT-S/14 (burn, Rust) against an independent
numpy forward pass of the same architecture on small random weights, in both key layouts;
the weights-free pooled encoder against its definition.

The reference follows the published model (facebookresearch/dinov2, Hugging Face
`Dinov2Model`): bilinear resize to 224 (align_corners=False), ImageNet normalisation, 14 x 14
patches, the 37 x 37 position embedding resampled bicubically (A = -0.75) with scale factor
(16 + 0.1) / 37, 12 pre-norm blocks (6 heads of 64, exact GELU, LayerScale, LN eps 1e-6), the
final norm's CLS token. It is written with numpy matrices (interpolation as matrix products,
attention as batched matrix products), in float64, sharing no code with the Rust one.
"""

from __future__ import annotations

import json
import math
import struct
import subprocess
import zlib
from pathlib import Path

import numpy as np
import pytest

DIM, DEPTH, HEADS, HIDDEN, PATCH, GRID_W = 384, 12, 6, 1536, 14, 37
MEAN = np.array([0.485, 0.456, 0.406])
STD = np.array([0.229, 0.224, 0.225])


# ---------------------------------------------------------------- files


def write_png(path: Path, rgb: np.ndarray) -> None:
    """An 8-bit RGB PNG (stdlib only)."""
    h, w, _ = rgb.shape
    raw = b"".join(b"\x00" + rgb[y].astype(np.uint8).tobytes() for y in range(h))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(raw))
                     + chunk(b"IEND", b""))


def write_safetensors(path: Path, tensors: dict[str, np.ndarray], dtype: str = "F32") -> None:
    """The safetensors format: u64 header length, JSON header, raw little-endian data."""
    np_dtype = {"F32": "<f4", "F16": "<f2"}[dtype]
    header, blobs, offset = {}, [], 0
    for name, t in tensors.items():
        b = np.ascontiguousarray(t, dtype=np_dtype).tobytes()
        header[name] = {"dtype": dtype, "shape": list(t.shape), "data_offsets": [offset, offset + len(b)]}
        blobs.append(b)
        offset += len(b)
    h = json.dumps(header).encode()
    h += b" " * ((8 - len(h) % 8) % 8)
    path.write_bytes(struct.pack("<Q", len(h)) + h + b"".join(blobs))


def random_weights(seed: int = 0) -> dict[str, np.ndarray]:
    """ViT-S/14 with small random weights, original/timm names, float32 values."""
    rng = np.random.default_rng(seed)
    n = lambda *s, scale=0.02: (rng.standard_normal(s) * scale).astype(np.float32)  # noqa: E731
    w = {
        "cls_token": n(1, 1, DIM, scale=0.1),
        "mask_token": n(1, DIM),
        "pos_embed": n(1, 1 + GRID_W * GRID_W, DIM, scale=0.3),
        "patch_embed.proj.weight": n(DIM, 3, PATCH, PATCH, scale=0.3),
        "patch_embed.proj.bias": n(DIM, scale=0.1),
        "norm.weight": 1 + n(DIM, scale=0.1),
        "norm.bias": n(DIM, scale=0.1),
    }
    for i in range(DEPTH):
        b = f"blocks.{i}"
        w |= {
            f"{b}.norm1.weight": 1 + n(DIM, scale=0.1), f"{b}.norm1.bias": n(DIM, scale=0.1),
            f"{b}.attn.qkv.weight": n(3 * DIM, DIM, scale=0.06), f"{b}.attn.qkv.bias": n(3 * DIM),
            f"{b}.attn.proj.weight": n(DIM, DIM, scale=0.05), f"{b}.attn.proj.bias": n(DIM),
            f"{b}.ls1.gamma": 0.3 + n(DIM, scale=0.1),
            f"{b}.norm2.weight": 1 + n(DIM, scale=0.1), f"{b}.norm2.bias": n(DIM, scale=0.1),
            f"{b}.mlp.fc1.weight": n(HIDDEN, DIM, scale=0.05), f"{b}.mlp.fc1.bias": n(HIDDEN),
            f"{b}.mlp.fc2.weight": n(DIM, HIDDEN, scale=0.03), f"{b}.mlp.fc2.bias": n(DIM),
            f"{b}.ls2.gamma": 0.3 + n(DIM, scale=0.1),
        }
    return w


def to_hugging_face(w: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The same weights with facebook/dinov2-small's names (q, k, v split)."""
    hf = {
        "embeddings.cls_token": w["cls_token"],
        "embeddings.mask_token": w["mask_token"],
        "embeddings.position_embeddings": w["pos_embed"],
        "embeddings.patch_embeddings.projection.weight": w["patch_embed.proj.weight"],
        "embeddings.patch_embeddings.projection.bias": w["patch_embed.proj.bias"],
        "layernorm.weight": w["norm.weight"],
        "layernorm.bias": w["norm.bias"],
    }
    for i in range(DEPTH):
        b, e = f"blocks.{i}", f"encoder.layer.{i}"
        q, k, v = np.split(w[f"{b}.attn.qkv.weight"], 3)
        qb, kb, vb = np.split(w[f"{b}.attn.qkv.bias"], 3)
        for part, t, tb in (("query", q, qb), ("key", k, kb), ("value", v, vb)):
            hf[f"{e}.attention.attention.{part}.weight"] = t
            hf[f"{e}.attention.attention.{part}.bias"] = tb
        hf |= {
            f"{e}.attention.output.dense.weight": w[f"{b}.attn.proj.weight"],
            f"{e}.attention.output.dense.bias": w[f"{b}.attn.proj.bias"],
            f"{e}.layer_scale1.lambda1": w[f"{b}.ls1.gamma"],
            f"{e}.layer_scale2.lambda1": w[f"{b}.ls2.gamma"],
        }
        for sub in ("norm1", "norm2", "mlp.fc1", "mlp.fc2"):
            for p in ("weight", "bias"):
                hf[f"{e}.{sub}.{p}"] = w[f"{b}.{sub}.{p}"]
    return hf


# ---------------------------------------------------------------- the reference


def linear_matrix(n_in: int, n_out: int) -> np.ndarray:
    """[n_out, n_in] bilinear resampling (align_corners=False, source clamped at 0)."""
    m = np.zeros((n_out, n_in))
    src = np.maximum((np.arange(n_out) + 0.5) * n_in / n_out - 0.5, 0.0)
    i0 = np.minimum(np.floor(src).astype(int), n_in - 1)
    i1 = np.minimum(i0 + 1, n_in - 1)
    t = src - i0
    np.add.at(m, (np.arange(n_out), i0), 1 - t)
    np.add.at(m, (np.arange(n_out), i1), t)
    return m


def cubic_matrix(n_in: int, n_out: int, scale: float) -> np.ndarray:
    """[n_out, n_in] bicubic resampling with scale factor `scale`, taps clamped."""
    a = -0.75

    def kernel(x: np.ndarray) -> np.ndarray:
        x = np.abs(x)
        near = ((a + 2) * x - (a + 3)) * x * x + 1
        far = ((a * x - 5 * a) * x + 8 * a) * x - 4 * a
        return np.where(x <= 1, near, np.where(x < 2, far, 0.0))

    m = np.zeros((n_out, n_in))
    src = (np.arange(n_out) + 0.5) / scale - 0.5
    base = np.floor(src).astype(int)
    for d in (-1, 0, 1, 2):
        idx = np.clip(base + d, 0, n_in - 1)
        np.add.at(m, (np.arange(n_out), idx), kernel(src - (base + d)))
    return m


def layer_norm(x: np.ndarray, w: np.ndarray, b: np.ndarray) -> np.ndarray:
    mu = x.mean(-1, keepdims=True)
    var = ((x - mu) ** 2).mean(-1, keepdims=True)
    return (x - mu) / np.sqrt(var + 1e-6) * w + b


def gelu(x: np.ndarray) -> np.ndarray:
    return 0.5 * x * (1 + np.vectorize(math.erf)(x / math.sqrt(2)))


def reference_features(w: dict[str, np.ndarray], rgb: np.ndarray) -> np.ndarray:
    w = {k: v.astype(np.float64) for k, v in w.items()}
    h_in, w_in, _ = rgb.shape
    img = rgb.astype(np.float64) / 255.0
    ry, rx = linear_matrix(h_in, 224), linear_matrix(w_in, 224)
    img = np.einsum("yi,ijc,xj->cyx", ry, img, rx, optimize=True)
    img = (img - MEAN[:, None, None]) / STD[:, None, None]
    g = 224 // PATCH
    patches = img.reshape(3, g, PATCH, g, PATCH).transpose(1, 3, 0, 2, 4).reshape(g * g, -1)
    x = patches @ w["patch_embed.proj.weight"].reshape(DIM, -1).T + w["patch_embed.proj.bias"]
    pos = w["pos_embed"][0]
    grid = pos[1:].reshape(GRID_W, GRID_W, DIM)
    c = cubic_matrix(GRID_W, g, (g + 0.1) / GRID_W)
    patch_pos = np.einsum("yi,ijd,xj->yxd", c, grid, c, optimize=True).reshape(g * g, DIM)
    x = np.concatenate([w["cls_token"][0] + pos[:1], x + patch_pos])
    hd = DIM // HEADS
    for i in range(DEPTH):
        b = f"blocks.{i}"
        h = layer_norm(x, w[f"{b}.norm1.weight"], w[f"{b}.norm1.bias"])
        qkv = (h @ w[f"{b}.attn.qkv.weight"].T + w[f"{b}.attn.qkv.bias"]).reshape(len(x), 3, HEADS, hd)
        q, k, v = (qkv[:, j].transpose(1, 0, 2) for j in range(3))  # [heads, tokens, hd]
        s = q @ k.transpose(0, 2, 1) / math.sqrt(hd)
        s = np.exp(s - s.max(-1, keepdims=True))
        s /= s.sum(-1, keepdims=True)
        o = (s @ v).transpose(1, 0, 2).reshape(len(x), DIM)
        x = x + w[f"{b}.ls1.gamma"] * (o @ w[f"{b}.attn.proj.weight"].T + w[f"{b}.attn.proj.bias"])
        h = layer_norm(x, w[f"{b}.norm2.weight"], w[f"{b}.norm2.bias"])
        m = gelu(h @ w[f"{b}.mlp.fc1.weight"].T + w[f"{b}.mlp.fc1.bias"])
        x = x + w[f"{b}.ls2.gamma"] * (m @ w[f"{b}.mlp.fc2.weight"].T + w[f"{b}.mlp.fc2.bias"])
    return layer_norm(x, w["norm.weight"], w["norm.bias"])[0]


# ---------------------------------------------------------------- tests


def make_image(seed: int = 1) -> np.ndarray:
    """A 128 x 128 camera-sized image: gradients, a disc and noise."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:128, 0:128]
    cx, cy = rng.integers(30, 98, 2)
    img = np.stack([x * 2, y * 2, 255 - x - y // 2], -1).astype(float)
    if seed % 2 == 0:
        img = 255 - img.transpose(1, 0, 2)
    img[(x - cx) ** 2 + (y - cy) ** 2 < 400] = rng.integers(0, 255, 3)
    img += rng.integers(-20, 20, img.shape)
    return np.clip(img, 0, 255).astype(np.uint8)


def encode(binary: Path, *args: str) -> list[dict]:
    out = subprocess.run([str(binary), "encode", *args, "--json"], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    return [json.loads(line) for line in out.stdout.splitlines()]


@pytest.fixture(scope="module")
def dinov2_files(tmp_path_factory) -> tuple[Path, Path, dict[str, np.ndarray]]:
    d = tmp_path_factory.mktemp("dinov2")
    w = random_weights()
    write_safetensors(d / "original.safetensors", w)
    # the Hugging Face layout, its tensors in another order and under a model prefix
    hf = {f"dinov2.{k}": v for k, v in reversed(to_hugging_face(w).items())}
    write_safetensors(d / "hf.safetensors", hf)
    return d / "original.safetensors", d / "hf.safetensors", w


def test_dinov2_matches_numpy_reference_in_both_layouts(modesuite_bin, dinov2_files, tmp_path):
    original, hf, w = dinov2_files
    images = []
    for seed in (1, 2):
        rgb = make_image(seed)
        p = tmp_path / f"img{seed}.png"
        write_png(p, rgb)
        images.append((p, rgb))
    paths = [str(p) for p, _ in images]
    ours_orig = encode(modesuite_bin, *paths, "--encoder", "dinov2", "--weights", str(original))
    ours_hf = encode(modesuite_bin, *paths, "--encoder", "dinov2", "--weights", str(hf))
    for (p, rgb), a, b in zip(images, ours_orig, ours_hf):
        assert a["dim"] == 384 and a["encoder"] == "dinov2"
        # both key layouts load the same model: identical features
        assert a["feature"] == b["feature"], p
        ref = reference_features(w, rgb)
        f = np.array(a["feature"], dtype=np.float64)
        cos = float(f @ ref / np.linalg.norm(f) / np.linalg.norm(ref))
        max_abs = float(np.abs(f - ref).max())
        print(f"{p.name}: cosine {cos:.8f} (tolerance >= 0.9999), max |diff| {max_abs:.2e} "
              f"(tolerance 1e-4), |ref| {np.linalg.norm(ref):.2f}")
        assert cos >= 0.9999
        # stricter than the cosine: a position embedding resampled without DINOv2's 0.1 offset
        # gives 6e-3 here, the tanh GELU 7e-4
        assert max_abs <= 1e-4
    # the image-dependent part matches too: the features' difference between the two images
    # against the reference's (so the comparison is not carried by the image-free CLS token)
    f1, f2 = (np.array(x["feature"]) for x in ours_orig)
    r1, r2 = (reference_features(w, rgb) for _, rgb in images)
    d, rd = f1 - f2, r1 - r2
    cos_d = float(d @ rd / np.linalg.norm(d) / np.linalg.norm(rd))
    rel = float(np.linalg.norm(rd) / np.linalg.norm(r1))
    print(f"difference of the two images' features: cosine {cos_d:.6f} (tolerance >= 0.999), "
          f"|r1 - r2| / |r1| = {rel:.3f}")
    assert cos_d >= 0.999
    assert rel > 0.01


def test_dinov2_half_precision_and_bad_files(modesuite_bin, dinov2_files, tmp_path):
    original, _, w = dinov2_files
    img = tmp_path / "img.png"
    write_png(img, make_image(3))
    half = tmp_path / "half.safetensors"
    write_safetensors(half, w, dtype="F16")
    f32 = np.array(encode(modesuite_bin, str(img), "--encoder", "dinov2", "--weights", str(original))[0]["feature"])
    f16 = np.array(encode(modesuite_bin, str(img), "--encoder", "dinov2", "--weights", str(half))[0]["feature"])
    cos = float(f32 @ f16 / np.linalg.norm(f32) / np.linalg.norm(f16))
    print(f"F16 weights vs F32: cosine {cos:.6f} (tolerance >= 0.999)")
    assert cos >= 0.999

    def fails(weights: Path, *expect: str) -> None:
        r = subprocess.run([str(modesuite_bin), "encode", str(img), "--encoder", "dinov2", "--weights", str(weights)],
                           capture_output=True, text=True)
        assert r.returncode == 2, r.stderr
        for e in expect:
            assert e in r.stderr, r.stderr

    broken = dict(w)
    del broken["blocks.3.mlp.fc2.bias"]
    write_safetensors(tmp_path / "missing.safetensors", broken)
    fails(tmp_path / "missing.safetensors", "missing tensor blocks.3.mlp.fc2.bias")
    bad = dict(w) | {"norm.bias": np.zeros(10, np.float32)}
    write_safetensors(tmp_path / "shape.safetensors", bad)
    fails(tmp_path / "shape.safetensors", "norm.bias has shape [10], expected [384]")
    (tmp_path / "junk.safetensors").write_bytes(b"not a model")
    fails(tmp_path / "junk.safetensors", "not a safetensors file")
    write_safetensors(tmp_path / "other.safetensors", {"weight": np.zeros(3, np.float32)})
    fails(tmp_path / "other.safetensors", "no cls_token")
    r = subprocess.run([str(modesuite_bin), "encode", str(img), "--encoder", "dinov2"], capture_output=True, text=True)
    assert r.returncode == 2 and "needs the weights file" in r.stderr, r.stderr


def test_pooled_encoder_is_the_grid_mean(modesuite_bin, tmp_path):
    rgb = make_image(4)[:100, :90]  # not a multiple of the grid
    p = tmp_path / "img.png"
    write_png(p, rgb)
    f = np.array(encode(modesuite_bin, str(p))[0]["feature"]).reshape(8, 8, 4)
    h, w, _ = rgb.shape
    for cy in range(8):
        for cx in range(8):
            cell = rgb[cy * h // 8:(cy + 1) * h // 8, cx * w // 8:(cx + 1) * w // 8] / 255.0
            np.testing.assert_allclose(f[cy, cx, :3], cell.reshape(-1, 3).mean(0), atol=1e-6)
    assert np.all(f[:, :, 3] == 0.0)  # no depth in a PNG


def test_python_encoder_equals_the_cli(modesuite_bin, dinov2_files, tmp_path):
    import modesuite

    original, _, _ = dinov2_files
    rgbs = [make_image(5), make_image(6)]  # the second a transposed (strided) view
    for i, rgb in enumerate(rgbs):
        write_png(tmp_path / f"p{i}.png", rgb)
    paths = [str(tmp_path / f"p{i}.png") for i in range(2)]
    for name, extra in (("pooled", []), ("dinov2", ["--weights", str(original)])):
        enc = modesuite.Encoder(name, weights=original if name == "dinov2" else None)
        assert enc.name == name
        cli = encode(modesuite_bin, *paths, "--encoder", name, *extra)
        batch = enc.encode(np.stack(rgbs))
        assert batch.shape == (2, enc.dim) and batch.dtype == np.float32
        for i, rgb in enumerate(rgbs):
            one = enc.encode(rgb)
            # the same numbers, bit for bit, one at a time, in a batch and through the CLI
            assert np.array_equal(one, batch[i])
            assert np.array_equal(one, np.array(cli[i]["feature"], dtype=np.float32)), name
    pooled = modesuite.Encoder()
    depth = np.full((128, 128), 2.5, dtype=np.float32)
    f = pooled.encode(rgbs[0], depth)
    assert np.allclose(f.reshape(8, 8, 4)[:, :, 3], 0.5)
    with pytest.raises(ValueError, match="expected \\(h, w, 3\\)"):
        pooled.encode(np.zeros((4, 4), dtype=np.uint8))
    with pytest.raises(ValueError, match="depth of shape"):
        pooled.encode(rgbs[0], np.zeros((3, 3), dtype=np.float32))
    with pytest.raises(ValueError, match="unknown"):
        modesuite.Encoder("clip")
    with pytest.raises(ValueError, match="needs the weights file"):
        modesuite.Encoder("dinov2")
