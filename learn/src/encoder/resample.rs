//! Image and grid resampling with PyTorch's `interpolate` arithmetic (`align_corners=False`,
//! no antialiasing), so that features match models trained with it.

/// Source coordinate of output index `o` for a scale `in/out` (PyTorch's
/// `area_pixel_compute_source_index`); linear interpolation clamps it at 0, cubic does not.
fn source(o: usize, inv_scale: f64, clamp: bool) -> f64 {
    let s = (o as f64 + 0.5) * inv_scale - 0.5;
    if clamp {
        s.max(0.0)
    } else {
        s
    }
}

/// Bilinear resize of an RGB image (bytes, row-major) to `out x out`, as planes of `f32` in
/// 0..1 (`[3][out][out]`).
pub(crate) fn resize_rgb(rgb: &[u8], width: usize, height: usize, out: usize) -> Vec<f32> {
    let taps = |len: usize| -> Vec<(usize, usize, f64)> {
        let inv = len as f64 / out as f64;
        (0..out)
            .map(|o| {
                let s = source(o, inv, true);
                let i0 = (s.floor() as usize).min(len - 1);
                let i1 = if i0 + 1 < len { i0 + 1 } else { i0 };
                (i0, i1, s - i0 as f64)
            })
            .collect()
    };
    let (tx, ty) = (taps(width), taps(height));
    let mut planes = vec![0.0f32; 3 * out * out];
    for (oy, &(y0, y1, ly)) in ty.iter().enumerate() {
        for (ox, &(x0, x1, lx)) in tx.iter().enumerate() {
            for c in 0..3 {
                let px = |y: usize, x: usize| f64::from(rgb[3 * (y * width + x) + c]) / 255.0;
                let top = (1.0 - lx) * px(y0, x0) + lx * px(y0, x1);
                let bottom = (1.0 - lx) * px(y1, x0) + lx * px(y1, x1);
                planes[(c * out + oy) * out + ox] = ((1.0 - ly) * top + ly * bottom) as f32;
            }
        }
    }
    planes
}

/// Keys' cubic convolution weights for fraction `t` (PyTorch's, `A = -0.75`), taps -1..=2.
fn cubic_weights(t: f64) -> [f64; 4] {
    const A: f64 = -0.75;
    let near = |x: f64| ((A + 2.0) * x - (A + 3.0)) * x * x + 1.0;
    let far = |x: f64| ((A * x - 5.0 * A) * x + 8.0 * A) * x - 4.0 * A;
    [far(t + 1.0), near(t), near(1.0 - t), far(2.0 - t)]
}

/// Bicubic resampling of an `m x m` grid of `channels`-vectors (`[y][x][c]`) to `out x out`
/// with the scale factor `scale` (output = input x scale), taps clamped at the borders
/// (`torch.nn.functional.interpolate(mode="bicubic", scale_factor=scale)`).
pub(crate) fn bicubic_grid(
    grid: &[f64],
    m: usize,
    channels: usize,
    out: usize,
    scale: f64,
) -> Vec<f64> {
    let taps: Vec<([usize; 4], [f64; 4])> = (0..out)
        .map(|o| {
            let s = source(o, 1.0 / scale, false);
            let i = s.floor();
            let w = cubic_weights(s - i);
            let idx = [-1i64, 0, 1, 2].map(|d| (i as i64 + d).clamp(0, m as i64 - 1) as usize);
            (idx, w)
        })
        .collect();
    let mut res = vec![0.0f64; out * out * channels];
    for (oy, (iy, wy)) in taps.iter().enumerate() {
        for (ox, (ix, wx)) in taps.iter().enumerate() {
            let dst = &mut res[(oy * out + ox) * channels..][..channels];
            for (a, &y) in iy.iter().enumerate() {
                for (b, &x) in ix.iter().enumerate() {
                    let w = wy[a] * wx[b];
                    let src = &grid[(y * m + x) * channels..][..channels];
                    for (d, s) in dst.iter_mut().zip(src) {
                        *d += w * s;
                    }
                }
            }
        }
    }
    res
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cubic_weights_sum_to_one_and_interpolate() {
        for t in [0.0, 0.25, 0.5, 0.9] {
            let w = cubic_weights(t);
            assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12, "{t}: {w:?}");
        }
        assert_eq!(cubic_weights(0.0), [0.0, 1.0, 0.0, 0.0]);
    }

    #[test]
    fn identity_and_constant_resampling() {
        // scale 1 reproduces the grid; a constant grid stays constant at any scale
        let m = 5;
        let grid: Vec<f64> = (0..m * m * 2).map(|i| (i as f64).sin()).collect();
        let same = bicubic_grid(&grid, m, 2, m, 1.0);
        for (a, b) in same.iter().zip(&grid) {
            assert!((a - b).abs() < 1e-12);
        }
        let flat = vec![0.5; 37 * 37];
        for v in bicubic_grid(&flat, 37, 1, 16, 16.1 / 37.0) {
            assert!((v - 0.5).abs() < 1e-12, "{v}");
        }
        // bilinear resize of a constant image
        let rgb = vec![51u8; 3 * 7 * 3];
        for v in resize_rgb(&rgb, 7, 3, 10) {
            assert!((v - 0.2).abs() < 1e-6, "{v}");
        }
    }

    #[test]
    fn bilinear_upsampling_of_two_pixels() {
        // a 2 x 1 image (0 and 255 in red) upsampled to 4: PyTorch gives 0, 0.25, 0.75, 1
        let rgb = [0u8, 0, 0, 255, 0, 0];
        let out = resize_rgb(&rgb, 2, 1, 4);
        let red_row0 = &out[0..4];
        assert_eq!(red_row0, &[0.0, 0.25, 0.75, 1.0]);
    }
}
