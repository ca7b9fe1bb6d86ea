// The GPU renderer's shaders (DESIGN §10); the CPU twin is src/warp/draw.rs, whose
// arithmetic these follow step for step.

// ---- Appearance: a = ā + P_a b_a, scattered into the padded reference image ----

struct Dims {
    // Reference image width and height.
    width: u32,
    height: u32,
    // Texels per row of `reference_out` (the row stride a buffer → texture copy needs).
    stride: u32,
    // Appearance parameters.
    n_params: u32,
    // Values per appearance vector (mask pixels × 3).
    dim: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> dims: Dims;
// Row 0: the mean ā; row k + 1: component k (each `dim` values).
@group(0) @binding(1) var<storage, read> basis: array<f32>;
// Per reference-image pixel: the mask pixel whose value it holds (mask or padding), or −1.
@group(0) @binding(2) var<storage, read> source_pixel: array<i32>;
// Per mask pixel: the feathered alpha (1 everywhere for a hard edge).
@group(0) @binding(3) var<storage, read> alpha: array<f32>;
// b_a of the frame.
@group(0) @binding(4) var<storage, read> params: array<f32>;
@group(0) @binding(5) var<storage, read_write> reference_out: array<vec4<f32>>;

@compute @workgroup_size(64)
fn appearance(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if (i >= dims.width * dims.height) {
        return;
    }
    let x = i % dims.width;
    let y = i / dims.width;
    let s = source_pixel[i];
    var v = vec4<f32>(0.0, 0.0, 0.0, 0.0);
    if (s >= 0) {
        let base = u32(s) * 3u;
        var r = basis[base];
        var g = basis[base + 1u];
        var b = basis[base + 2u];
        // Components in order, as the CPU's reconstruct_into adds them.
        for (var k = 0u; k < dims.n_params; k = k + 1u) {
            let c = (k + 1u) * dims.dim + base;
            let w = params[k];
            r = r + w * basis[c];
            g = g + w * basis[c + 1u];
            b = b + w * basis[c + 2u];
        }
        v = vec4<f32>(r, g, b, alpha[u32(s)]);
    }
    reference_out[y * dims.stride + x] = v;
}

// ---- Warp: one quad per triangle (its bounding box grown by the dilation) ----

struct Canvas {
    // Canvas width and height, pixels.
    size: vec2<f32>,
    // Reference image width and height, pixels.
    reference_size: vec2<f32>,
}

@group(0) @binding(0) var<uniform> canvas: Canvas;
@group(0) @binding(1) var reference: texture_2d<f32>;

// Per triangle (instance), as `Tri` of src/warp/draw.rs: barycentric λ_i relative to the
// origin, λ_i(p) = la_i + lx_i·(p.x − o.x) + ly_i·(p.y − o.y); the floor each λ_i may reach
// (negative across a hull edge); the vertices in the reference frame.
struct Instance {
    // The quad: first and one-past-last pixel column and row.
    @location(0) quad: vec4<f32>,
    // Origin (x, y), source vertex 0 (x, y).
    @location(1) origin_src0: vec4<f32>,
    // Source vertices 1 and 2.
    @location(2) src12: vec4<f32>,
    @location(3) la: vec4<f32>,
    @location(4) lx: vec4<f32>,
    @location(5) ly: vec4<f32>,
    @location(6) floor: vec4<f32>,
}

struct Varyings {
    @builtin(position) position: vec4<f32>,
    @location(0) @interpolate(flat) origin_src0: vec4<f32>,
    @location(1) @interpolate(flat) src12: vec4<f32>,
    @location(2) @interpolate(flat) la: vec4<f32>,
    @location(3) @interpolate(flat) lx: vec4<f32>,
    @location(4) @interpolate(flat) ly: vec4<f32>,
    @location(5) @interpolate(flat) floor: vec4<f32>,
}

@vertex
fn quad(@builtin(vertex_index) corner: u32, t: Instance) -> Varyings {
    // Two triangles: (0,0) (1,0) (0,1), (0,1) (1,0) (1,1).
    var cx = array<f32, 6>(0.0, 1.0, 0.0, 0.0, 1.0, 1.0);
    var cy = array<f32, 6>(0.0, 0.0, 1.0, 1.0, 0.0, 1.0);
    let px = mix(t.quad.x, t.quad.z, cx[corner]);
    let py = mix(t.quad.y, t.quad.w, cy[corner]);
    var out: Varyings;
    out.position = vec4<f32>(px / canvas.size.x * 2.0 - 1.0, 1.0 - py / canvas.size.y * 2.0, 0.0, 1.0);
    out.origin_src0 = t.origin_src0;
    out.src12 = t.src12;
    out.la = t.la;
    out.lx = t.lx;
    out.ly = t.ly;
    out.floor = t.floor;
    return out;
}

fn fetch(x: i32, y: i32) -> vec4<f32> {
    return textureLoad(reference, vec2<i32>(x, y), 0);
}

// Bilinear sample with pixel centres at integers, clamped to the border (warp::sample).
fn bilinear(s: vec2<f32>) -> vec4<f32> {
    let last = canvas.reference_size - vec2<f32>(1.0, 1.0);
    let c = clamp(s, vec2<f32>(0.0, 0.0), last);
    let x0 = i32(floor(c.x));
    let y0 = i32(floor(c.y));
    let x1 = min(x0 + 1, i32(last.x));
    let y1 = min(y0 + 1, i32(last.y));
    let fx = c.x - f32(x0);
    let fy = c.y - f32(y0);
    let top = fetch(x0, y0) * (1.0 - fx) + fetch(x1, y0) * fx;
    let bottom = fetch(x0, y1) * (1.0 - fx) + fetch(x1, y1) * fx;
    return top * (1.0 - fy) + bottom * fy;
}

fn face(v: Varyings) -> vec4<f32> {
    // The CPU's pixel (x, y) has its centre at framebuffer (x + 0.5, y + 0.5).
    let p = v.position.xy - vec2<f32>(0.5, 0.5) - v.origin_src0.xy;
    let l = v.la.xyz + v.lx.xyz * p.x + v.ly.xyz * p.y;
    if (any(l < v.floor.xyz)) {
        discard;
    }
    var c = l;
    if (any(l < vec3<f32>(0.0, 0.0, 0.0))) {
        // Dilated pixel beyond a hull edge: the nearest point of the triangle.
        c = max(l, vec3<f32>(0.0, 0.0, 0.0));
        c = c / (c.x + c.y + c.z);
    }
    let s = c.x * v.origin_src0.zw + c.y * v.src12.xy + c.z * v.src12.zw;
    return bilinear(s);
}

@fragment
fn hard(v: Varyings) -> @location(0) vec4<f32> {
    let f = face(v);
    return vec4<f32>(f.rgb / 255.0, 1.0);
}

@fragment
fn feathered(v: Varyings) -> @location(0) vec4<f32> {
    let f = face(v);
    return vec4<f32>(f.rgb / 255.0, clamp(f.a, 0.0, 1.0));
}
