// modesuite-render viewer: draws an offscreen colour image over the whole window, with the
// heads-up text image (RGBA, alpha = coverage) composited 1:1 at the top-left corner.

@group(0) @binding(0) var blit_src: texture_2d<f32>;
@group(0) @binding(1) var blit_sampler: sampler;
@group(0) @binding(2) var blit_hud: texture_2d<f32>;

struct BlitOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) uv: vec2<f32>,
};

@vertex
fn vs_blit(@builtin(vertex_index) i: u32) -> BlitOut {
    let x = f32((i << 1u) & 2u);
    let y = f32(i & 2u);
    var out: BlitOut;
    out.clip = vec4<f32>(x * 2.0 - 1.0, 1.0 - y * 2.0, 0.0, 1.0);
    out.uv = vec2<f32>(x, y);
    return out;
}

@fragment
fn fs_blit(in: BlitOut) -> @location(0) vec4<f32> {
    var c = textureSampleLevel(blit_src, blit_sampler, in.uv, 0.0);
    let px = vec2<u32>(in.clip.xy);
    let hud_size = textureDimensions(blit_hud);
    if (px.x < hud_size.x && px.y < hud_size.y) {
        let h = textureLoad(blit_hud, px, 0);
        c = vec4<f32>(mix(c.rgb, h.rgb, h.a), 1.0);
    }
    return c;
}
