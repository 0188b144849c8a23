//! Oriented boxes, rounded boxes and the signed distance between convex quadrilaterals.

/// A 2-D point or vector (x, y), float32.
pub(crate) type Point = [f32; 2];

/// `u × v = u_x v_y − u_y v_x`.
pub(crate) fn cross(u: Point, v: Point) -> f32 {
    u[0] * v[1] - u[1] * v[0]
}

fn dot(u: Point, v: Point) -> f32 {
    u[0] * v[0] + u[1] * v[1]
}

fn sub(a: Point, b: Point) -> Point {
    [a[0] - b[0], a[1] - b[1]]
}

/// The four xy corners of a box, counter-clockwise in the order (+L/2,+W/2), (−L/2,+W/2),
/// (−L/2,−W/2), (+L/2,−W/2) of the body frame, rotated by the heading and shifted by the
/// centre (as the official box code: rotation first, then translation).
pub(crate) fn box_corners(
    center_x_m: f32,
    center_y_m: f32,
    length_m: f32,
    width_m: f32,
    heading_rad: f32,
) -> [Point; 4] {
    let (s, c) = heading_rad.sin_cos();
    let l2 = length_m * 0.5;
    let w2 = width_m * 0.5;
    [(l2, w2), (-l2, w2), (-l2, -w2), (l2, -w2)]
        .map(|(lx, ly)| [c * lx - s * ly + center_x_m, s * lx + c * ly + center_y_m])
}

/// Corner rounding radius of a box: `0.7 · min(length, width) / 2`.
pub(crate) fn rounding_radius(length_m: f32, width_m: f32) -> f32 {
    length_m.min(width_m) * 0.7 / 2.0
}

/// Index of the lowest vertex (smallest y, then smallest x; first on exact ties).
fn lowest(poly: &[Point; 4]) -> usize {
    let mut best = 0;
    for k in 1..4 {
        let (p, b) = (poly[k], poly[best]);
        if p[1] < b[1] || (p[1] == b[1] && p[0] < b[0]) {
            best = k;
        }
    }
    best
}

/// The Minkowski sum `a ⊕ (−b)` of two counter-clockwise convex quadrilaterals, as an
/// 8-vertex counter-clockwise polygon (edges merged by angle from the lowest vertices; parallel
/// edges give collinear vertices, never zero-length edges for non-degenerate inputs).
pub(crate) fn minkowski_difference(a: &[Point; 4], b: &[Point; 4]) -> [Point; 8] {
    // −b is still counter-clockwise (a point reflection keeps the orientation).
    let nb = b.map(|p| [-p[0], -p[1]]);
    let (ia, ib) = (lowest(a), lowest(&nb));
    let edge = |poly: &[Point; 4], k: usize| sub(poly[(k + 1) % 4], poly[k % 4]);
    let mut out = [[0.0; 2]; 8];
    let (mut i, mut j) = (0, 0);
    for slot in &mut out {
        let p = a[(ia + i) % 4];
        let q = nb[(ib + j) % 4];
        *slot = [p[0] + q[0], p[1] + q[1]];
        // Take the edge with the smaller polar angle next (a's on ties).
        if j == 4 || (i < 4 && cross(edge(a, ia + i), edge(&nb, ib + j)) >= 0.0) {
            i += 1;
        } else {
            j += 1;
        }
    }
    out
}

/// Signed distance from the origin to a counter-clockwise convex polygon: the Euclidean
/// distance to its boundary, negative when the origin is inside.
pub(crate) fn signed_distance_from_origin(poly: &[Point; 8]) -> f32 {
    let mut inside = true;
    let mut min_d2 = f32::INFINITY;
    for k in 0..poly.len() {
        let a = poly[k];
        let e = sub(poly[(k + 1) % poly.len()], a);
        let to_origin = [-a[0], -a[1]];
        if cross(e, to_origin) < 0.0 {
            inside = false;
        }
        let len2 = dot(e, e);
        let t = if len2 > 0.0 {
            (dot(to_origin, e) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let r = [to_origin[0] - t * e[0], to_origin[1] - t * e[1]];
        min_d2 = min_d2.min(dot(r, r));
    }
    let d = min_d2.sqrt();
    if inside { -d } else { d }
}

/// Signed distance between two convex counter-clockwise quadrilaterals: the gap when they are
/// disjoint, minus the penetration depth when they overlap.
pub(crate) fn signed_distance_between_quads(a: &[Point; 4], b: &[Point; 4]) -> f32 {
    signed_distance_from_origin(&minkowski_difference(a, b))
}

/// Signed distance between two rounded boxes given by centre, size and heading (the
/// nearest-object feature between two objects, §5): distance between the core rectangles
/// minus both rounding radii.
#[cfg(test)]
pub(crate) fn rounded_box_distance(a: [f32; 5], b: [f32; 5]) -> f32 {
    let core = |[x, y, l, w, h]: [f32; 5]| {
        let r = rounding_radius(l, w);
        (box_corners(x, y, l - 2.0 * r, w - 2.0 * r, h), r)
    };
    let (ca, ra) = core(a);
    let (cb, rb) = core(b);
    signed_distance_between_quads(&ca, &cb) - ra - rb
}
