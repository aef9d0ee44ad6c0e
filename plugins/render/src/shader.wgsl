// modesuite-render: one lit, shadowed pass writing colour, linear depth and segmentation.
//
// Target 0: colour (sRGB). Target 1: (depth along the optical axis in metres, bit-cast to u32;
// segmentation id). Depth is written as integer bits because float render targets and depth
// texture copies are not portable to the GL backend (see STACK-NOTES).

struct View {
    view_proj: mat4x4<f32>,
    light_view_proj: mat4x4<f32>,
    // xyz: camera position (world), w: unused.
    cam_pos: vec4<f32>,
    // xyz: optical axis (world, unit), w: unused.
    cam_fwd: vec4<f32>,
    // xyz: direction the light travels (world, unit), w: ambient fraction.
    light_dir: vec4<f32>,
    // x: shadows on (1) or off (0), y: shadow-map texel size (uv), z: normal offset (m),
    // w: depth bias (light clip units).
    params: vec4<f32>,
};

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var shadow_map: texture_depth_2d;
@group(0) @binding(2) var shadow_sampler: sampler_comparison;

struct VertexIn {
    @location(0) pos: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) color: vec4<f32>,
    @location(3) id: u32,
    @location(4) flags: u32,
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) color: vec4<f32>,
    @location(3) depth: f32,
    @location(4) @interpolate(flat) id: u32,
    @location(5) @interpolate(flat) flags: u32,
};

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    var out: VertexOut;
    out.clip = view.view_proj * vec4<f32>(v.pos, 1.0);
    out.world = v.pos;
    out.normal = v.normal;
    out.color = v.color;
    out.depth = dot(v.pos - view.cam_pos.xyz, view.cam_fwd.xyz);
    out.id = v.id;
    out.flags = v.flags;
    return out;
}

@vertex
fn vs_shadow(v: VertexIn) -> @builtin(position) vec4<f32> {
    return view.light_view_proj * vec4<f32>(v.pos, 1.0);
}

fn lit_fraction(world: vec3<f32>, n: vec3<f32>) -> f32 {
    let p = view.light_view_proj * vec4<f32>(world + n * view.params.z, 1.0);
    let ndc = p.xyz / p.w;
    let uv = vec2<f32>(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5);
    if (uv.x < 0.0 || uv.x > 1.0 || uv.y < 0.0 || uv.y > 1.0 || ndc.z > 1.0) {
        return 1.0;
    }
    let t = view.params.y;
    let r = ndc.z - view.params.w;
    var sum = 0.0;
    sum += textureSampleCompareLevel(shadow_map, shadow_sampler, uv + vec2<f32>(-0.5, -0.5) * t, r);
    sum += textureSampleCompareLevel(shadow_map, shadow_sampler, uv + vec2<f32>(0.5, -0.5) * t, r);
    sum += textureSampleCompareLevel(shadow_map, shadow_sampler, uv + vec2<f32>(-0.5, 0.5) * t, r);
    sum += textureSampleCompareLevel(shadow_map, shadow_sampler, uv + vec2<f32>(0.5, 0.5) * t, r);
    return sum * 0.25;
}

struct FragmentOut {
    @location(0) color: vec4<f32>,
    @location(1) data: vec2<u32>,
};

fn shade(in: VertexOut, front: bool) -> vec4<f32> {
    var n = normalize(in.normal);
    // Both sides are lit (cloth, open meshes).
    if (!front) {
        n = -n;
    }
    let to_light = -view.light_dir.xyz;
    let ndl = max(dot(n, to_light), 0.0);
    var lit = 1.0;
    if (view.params.x > 0.5 && ndl > 0.0) {
        lit = lit_fraction(in.world, n);
    }
    var base = in.color.rgb;
    if ((in.flags & 1u) != 0u) {
        let k = (i32(floor(in.world.x * 2.0)) + i32(floor(in.world.y * 2.0))) & 1;
        base = base * select(1.0, 0.8, k == 1);
    }
    let ambient = view.light_dir.w;
    // A little sky light from above keeps faces turned away from the sun readable.
    let sky = 0.5 + 0.5 * n.z;
    let c = base * (ambient * (0.6 + 0.4 * sky) + (1.0 - ambient) * ndl * lit);
    return vec4<f32>(c, in.color.a);
}

@fragment
fn fs_main(in: VertexOut, @builtin(front_facing) front: bool) -> FragmentOut {
    var out: FragmentOut;
    out.color = shade(in, front);
    out.data = vec2<u32>(bitcast<u32>(in.depth), in.id);
    return out;
}

// Translucent markers: colour only.
@fragment
fn fs_marker(in: VertexOut, @builtin(front_facing) front: bool) -> @location(0) vec4<f32> {
    return shade(in, front);
}

// Contact and grasp markers: their own colour (shaded a little by the normal so spheres read
// as spheres), drawn over everything.
@fragment
fn fs_overlay(in: VertexOut, @builtin(front_facing) front: bool) -> @location(0) vec4<f32> {
    let n = normalize(in.normal);
    return vec4<f32>(in.color.rgb * (0.75 + 0.25 * max(n.z, 0.0)), in.color.a);
}
