//! A bounding volume hierarchy over a triangle mesh: closest-hit and any-hit ray
//! queries, closest-point queries and generalised winding numbers.
//!
//! * Build: binned surface-area heuristic (SAH; `MacDonald` & Booth 1990, binned as
//!   in Wald 2007) over triangle centroids, 16 bins per axis, leaves of at most
//!   [`MAX_LEAF_TRIANGLES`] triangles. Deep, unbalanced branches switch to object
//!   median splits, which bounds the tree depth.
//! * Rays: slab tests against node boxes, Möller–Trumbore ray–triangle
//!   intersection (Möller & Trumbore 1997) with inclusive barycentric bounds.
//! * Closest point: branch-and-bound on the squared distance to node boxes,
//!   closest point on a triangle by its Voronoi regions (Ericson 2005, §5.1.5).
//! * Winding number: the fast winding number of Barill et al. (SIGGRAPH 2018),
//!   first order: a node far from the query point (distance > `β·radius`, β = 2)
//!   contributes its area-weighted normal as a dipole, `N·(p̃ − q) / (4π|p̃ − q|³)`;
//!   nearby leaves contribute exact triangle solid angles
//!   (Van Oosterom & Strackee 1983). It is ≈ 1 inside a closed, outward-oriented
//!   mesh, ≈ 0 outside, and degrades gracefully for open meshes (a head cut at the
//!   neck), which is why the signed distance uses it rather than ray parity.
//!
//! Own implementation rather than a crate: the `bvh` crate pulls in nalgebra and
//! has no closest-point or winding-number queries; this one is f32 glam throughout.

use glam::{Vec3, Vec3A};

/// Most triangles in one leaf.
pub const MAX_LEAF_TRIANGLES: usize = 4;
/// SAH bins per axis.
const BINS: usize = 16;
/// Build depth after which splits become object-median splits (bounds the depth).
const MEDIAN_SPLIT_DEPTH: usize = 40;
/// Traversal stack size: depth ≤ `MEDIAN_SPLIT_DEPTH` + log2(2³²) + slack.
const STACK_SIZE: usize = 96;
/// Fast-winding-number accuracy parameter β (Barill et al. use 2).
const WINDING_BETA: f32 = 2.0;

/// A ray–triangle intersection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit: `origin + t · dir`.
    pub t: f32,
    /// Index of the triangle in the mesh.
    pub triangle: u32,
    /// Barycentric weight of the triangle's second corner.
    pub b1: f32,
    /// Barycentric weight of the triangle's third corner.
    pub b2: f32,
}

/// The closest point of the mesh to a query point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClosestPoint {
    /// The point on the surface.
    pub point: Vec3,
    /// Index of the triangle it lies on.
    pub triangle: u32,
    /// Barycentric weight of the triangle's second corner.
    pub b1: f32,
    /// Barycentric weight of the triangle's third corner.
    pub b2: f32,
    /// Euclidean distance from the query point.
    pub distance: f32,
}

/// One node: a box and either two children (`count == 0`, children at
/// `first_or_child` and `first_or_child + 1`) or `count` triangles starting at slot
/// `first_or_child`.
#[derive(Debug, Clone, Copy)]
struct Node {
    min: Vec3A,
    max: Vec3A,
    first_or_child: u32,
    count: u32,
}

/// Per-node data for the fast winding number.
#[derive(Debug, Clone, Copy)]
struct Dipole {
    /// `Σ ½ (b − a) × (c − a)` over the node's triangles.
    area_normal: Vec3A,
    /// Area-weighted centroid.
    centre: Vec3A,
    /// Radius of a ball around `centre` holding the node.
    radius: f32,
}

/// A triangle stored for intersection: corner `a` and edges `b − a`, `c − a`.
#[derive(Debug, Clone, Copy)]
struct Tri {
    a: Vec3A,
    e1: Vec3A,
    e2: Vec3A,
}

/// A BVH over a triangle list. Triangles keep their mesh indices in every answer.
#[derive(Debug, Clone)]
pub struct Bvh {
    nodes: Vec<Node>,
    dipoles: Vec<Dipole>,
    /// Triangles in leaf order.
    tris: Vec<Tri>,
    /// Mesh index of the triangle in each leaf slot.
    tri_index: Vec<u32>,
}

/// Axis-aligned box helper used by the build.
#[derive(Debug, Clone, Copy)]
struct Aabb {
    min: Vec3A,
    max: Vec3A,
}

impl Aabb {
    const EMPTY: Self = Self {
        min: Vec3A::splat(f32::INFINITY),
        max: Vec3A::splat(f32::NEG_INFINITY),
    };

    fn grow(&mut self, p: Vec3A) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    fn merge(&mut self, o: &Self) {
        self.min = self.min.min(o.min);
        self.max = self.max.max(o.max);
    }

    fn half_area(&self) -> f32 {
        let e = (self.max - self.min).max(Vec3A::ZERO);
        e.x * e.y + e.y * e.z + e.z * e.x
    }
}

impl Bvh {
    /// Builds the hierarchy. Indices must be valid for `positions` (see
    /// [`crate::mesh::Mesh::validate`]); an empty triangle list gives an empty tree
    /// that no ray hits.
    pub fn new(positions: &[Vec3], triangles: &[[u32; 3]]) -> Self {
        let n = triangles.len();
        let corners: Vec<[Vec3A; 3]> = triangles
            .iter()
            .map(|t| t.map(|i| Vec3A::from(positions[i as usize])))
            .collect();
        let mut boxes = Vec::with_capacity(n);
        let mut centroids = Vec::with_capacity(n);
        for c in &corners {
            let mut b = Aabb::EMPTY;
            for &p in c {
                b.grow(p);
            }
            boxes.push(b);
            centroids.push((c[0] + c[1] + c[2]) / 3.0);
        }
        let mut order: Vec<u32> = (0..n as u32).collect();
        let mut nodes = Vec::with_capacity(2 * n.max(1));
        nodes.push(Node {
            min: Vec3A::ZERO,
            max: Vec3A::ZERO,
            first_or_child: 0,
            count: n as u32,
        });
        // Work list: (node index, first slot, count, depth).
        let mut work = vec![(0usize, 0usize, n, 0usize)];
        while let Some((node, first, count, depth)) = work.pop() {
            let slots = &mut order[first..first + count];
            let mut bounds = Aabb::EMPTY;
            let mut centroid_bounds = Aabb::EMPTY;
            for &t in slots.iter() {
                bounds.merge(&boxes[t as usize]);
                centroid_bounds.grow(centroids[t as usize]);
            }
            nodes[node].min = bounds.min;
            nodes[node].max = bounds.max;
            nodes[node].first_or_child = first as u32;
            nodes[node].count = count as u32;
            if count <= 1 {
                continue;
            }
            let split = if depth >= MEDIAN_SPLIT_DEPTH {
                median_split(slots, &centroids, &centroid_bounds)
            } else {
                sah_split(slots, &boxes, &centroids, &bounds, &centroid_bounds)
            };
            let Some(left_count) = split else { continue };
            let child = nodes.len();
            nodes[node].first_or_child = child as u32;
            nodes[node].count = 0;
            for _ in 0..2 {
                nodes.push(Node {
                    min: Vec3A::ZERO,
                    max: Vec3A::ZERO,
                    first_or_child: 0,
                    count: 0,
                });
            }
            work.push((child, first, left_count, depth + 1));
            work.push((child + 1, first + left_count, count - left_count, depth + 1));
        }
        let tris = order
            .iter()
            .map(|&t| {
                let [a, b, c] = corners[t as usize];
                Tri {
                    a,
                    e1: b - a,
                    e2: c - a,
                }
            })
            .collect();
        let mut bvh = Self {
            nodes,
            dipoles: Vec::new(),
            tris,
            tri_index: order,
        };
        bvh.dipoles = bvh.compute_dipoles();
        bvh
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.tris.len()
    }

    /// Number of nodes (interior and leaves).
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Bounds `(min, max)` of all triangles (empty tree: an inverted box).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        if self.tris.is_empty() {
            return (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        }
        (self.nodes[0].min.into(), self.nodes[0].max.into())
    }

    /// Dipole data bottom-up (children always have larger indices than parents).
    fn compute_dipoles(&self) -> Vec<Dipole> {
        let mut out = vec![
            Dipole {
                area_normal: Vec3A::ZERO,
                centre: Vec3A::ZERO,
                radius: 0.0,
            };
            self.nodes.len()
        ];
        // Area-weighted sums first: (area normal, Σ area · centroid, Σ area).
        let mut sums = vec![(Vec3A::ZERO, Vec3A::ZERO, 0.0f32); self.nodes.len()];
        for i in (0..self.nodes.len()).rev() {
            let node = self.nodes[i];
            if self.tris.is_empty() {
                break;
            }
            if node.count > 0 {
                let mut s = (Vec3A::ZERO, Vec3A::ZERO, 0.0f32);
                for tri in
                    &self.tris[node.first_or_child as usize..(node.first_or_child + node.count) as usize]
                {
                    let n = 0.5 * tri.e1.cross(tri.e2);
                    let area = n.length();
                    s.0 += n;
                    s.1 += area * (tri.a + (tri.e1 + tri.e2) / 3.0);
                    s.2 += area;
                }
                sums[i] = s;
            } else {
                let (l, r) = (
                    sums[node.first_or_child as usize],
                    sums[node.first_or_child as usize + 1],
                );
                sums[i] = (l.0 + r.0, l.1 + r.1, l.2 + r.2);
            }
            let box_centre = 0.5 * (node.min + node.max);
            let centre = if sums[i].2 > 0.0 {
                sums[i].1 / sums[i].2
            } else {
                box_centre
            };
            // Farthest box corner bounds the node's extent around `centre`.
            let far = (centre - node.min).abs().max((node.max - centre).abs());
            out[i] = Dipole {
                area_normal: sums[i].0,
                centre,
                radius: far.length(),
            };
        }
        out
    }

    /// Closest intersection with `t ∈ [t_min, t_max]` of the ray `origin + t·dir`
    /// (`dir` need not be unit length; `t` is in its units).
    pub fn closest_hit(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<Hit> {
        if self.tris.is_empty() {
            return None;
        }
        let (origin, dir) = (Vec3A::from(origin), Vec3A::from(dir));
        let inv = dir.recip();
        let mut best_t = t_max;
        let mut best: Option<(usize, f32, f32)> = None;
        // Pending far children with their entry distances.
        let mut stack = [(0u32, 0.0f32); STACK_SIZE];
        let mut sp = 0usize;
        slab(&self.nodes[0], origin, inv, t_min, best_t)?;
        let mut node_index = 0usize;
        loop {
            let node = &self.nodes[node_index];
            if node.count > 0 {
                let first = node.first_or_child as usize;
                for slot in first..first + node.count as usize {
                    if let Some((t, u, v)) = intersect(&self.tris[slot], origin, dir, t_min, best_t) {
                        best_t = t;
                        best = Some((slot, u, v));
                    }
                }
            } else {
                let left = node.first_or_child as usize;
                let hl = slab(&self.nodes[left], origin, inv, t_min, best_t);
                let hr = slab(&self.nodes[left + 1], origin, inv, t_min, best_t);
                match (hl, hr) {
                    (Some(a), Some(b)) => {
                        let (near, far, far_t) = if a <= b {
                            (left, left + 1, b)
                        } else {
                            (left + 1, left, a)
                        };
                        stack[sp] = (far as u32, far_t);
                        sp += 1;
                        node_index = near;
                        continue;
                    }
                    (Some(_), None) => {
                        node_index = left;
                        continue;
                    }
                    (None, Some(_)) => {
                        node_index = left + 1;
                        continue;
                    }
                    (None, None) => {}
                }
            }
            // Pop the next node that the ray still enters before the best hit.
            loop {
                if sp == 0 {
                    return best.map(|(slot, b1, b2)| Hit {
                        t: best_t,
                        triangle: self.tri_index[slot],
                        b1,
                        b2,
                    });
                }
                sp -= 1;
                let (candidate, entry) = stack[sp];
                if entry <= best_t {
                    node_index = candidate as usize;
                    break;
                }
            }
        }
    }

    /// Whether any triangle intersects the ray for `t ∈ [t_min, t_max]`.
    pub fn any_hit(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> bool {
        if self.tris.is_empty() {
            return false;
        }
        let (origin, dir) = (Vec3A::from(origin), Vec3A::from(dir));
        let inv = dir.recip();
        let mut stack = [0u32; STACK_SIZE];
        let mut sp = 0usize;
        if slab(&self.nodes[0], origin, inv, t_min, t_max).is_none() {
            return false;
        }
        let mut node_index = 0usize;
        loop {
            let node = &self.nodes[node_index];
            if node.count > 0 {
                let first = node.first_or_child as usize;
                for tri in &self.tris[first..first + node.count as usize] {
                    if intersect(tri, origin, dir, t_min, t_max).is_some() {
                        return true;
                    }
                }
            } else {
                let left = node.first_or_child as usize;
                let hl = slab(&self.nodes[left], origin, inv, t_min, t_max).is_some();
                let hr = slab(&self.nodes[left + 1], origin, inv, t_min, t_max).is_some();
                match (hl, hr) {
                    (true, true) => {
                        stack[sp] = (left + 1) as u32;
                        sp += 1;
                        node_index = left;
                        continue;
                    }
                    (true, false) => {
                        node_index = left;
                        continue;
                    }
                    (false, true) => {
                        node_index = left + 1;
                        continue;
                    }
                    (false, false) => {}
                }
            }
            if sp == 0 {
                return false;
            }
            sp -= 1;
            node_index = stack[sp] as usize;
        }
    }

    /// Closest point of the surface to `query` among points closer than `max_distance`
    /// (pass `f32::INFINITY` for no limit).
    pub fn closest_point(&self, query: Vec3, max_distance: f32) -> Option<ClosestPoint> {
        if self.tris.is_empty() {
            return None;
        }
        let mut best_d2 = if max_distance.is_finite() {
            max_distance * max_distance
        } else {
            f32::INFINITY
        };
        let query = Vec3A::from(query);
        let mut best: Option<(usize, Vec3A, f32, f32)> = None;
        let mut stack = [0u32; STACK_SIZE];
        let mut sp = 0usize;
        stack[sp] = 0;
        sp += 1;
        while sp > 0 {
            sp -= 1;
            let node = &self.nodes[stack[sp] as usize];
            if box_distance2(node, query) > best_d2 {
                continue;
            }
            if node.count > 0 {
                let first = node.first_or_child as usize;
                for slot in first..first + node.count as usize {
                    let (p, b1, b2) = closest_on_triangle(&self.tris[slot], query);
                    let d2 = (p - query).length_squared();
                    if d2 <= best_d2 {
                        best_d2 = d2;
                        best = Some((slot, p, b1, b2));
                    }
                }
            } else {
                let left = node.first_or_child as usize;
                let dl = box_distance2(&self.nodes[left], query);
                let dr = box_distance2(&self.nodes[left + 1], query);
                // Push the farther child first so the nearer one is visited next.
                let (near, far) = if dl <= dr {
                    (left, left + 1)
                } else {
                    (left + 1, left)
                };
                stack[sp] = far as u32;
                stack[sp + 1] = near as u32;
                sp += 2;
            }
        }
        best.map(|(slot, point, b1, b2)| ClosestPoint {
            point: point.into(),
            triangle: self.tri_index[slot],
            b1,
            b2,
            distance: best_d2.sqrt(),
        })
    }

    /// Generalised winding number of the surface around `query` (fast, first-order
    /// approximation): ≈ 1 inside a closed outward-oriented mesh, ≈ 0 outside.
    pub fn winding_number(&self, query: Vec3) -> f32 {
        if self.tris.is_empty() {
            return 0.0;
        }
        let query = Vec3A::from(query);
        let mut total = 0.0f64;
        let mut stack = [0u32; STACK_SIZE];
        let mut sp = 0usize;
        stack[sp] = 0;
        sp += 1;
        while sp > 0 {
            sp -= 1;
            let index = stack[sp] as usize;
            let node = &self.nodes[index];
            let dipole = &self.dipoles[index];
            let r = dipole.centre - query;
            let dist = r.length();
            if dist > WINDING_BETA * dipole.radius {
                total += f64::from(dipole.area_normal.dot(r)) / f64::from(dist * dist * dist);
            } else if node.count > 0 {
                let first = node.first_or_child as usize;
                for tri in &self.tris[first..first + node.count as usize] {
                    total += triangle_solid_angle(tri, query);
                }
            } else {
                stack[sp] = node.first_or_child;
                stack[sp + 1] = node.first_or_child + 1;
                sp += 2;
            }
        }
        (total / (4.0 * std::f64::consts::PI)) as f32
    }

    /// Exact winding number by summing every triangle's solid angle (O(n); for tests
    /// and small meshes).
    pub fn winding_number_exact(&self, query: Vec3) -> f32 {
        let query = Vec3A::from(query);
        let total: f64 = self.tris.iter().map(|t| triangle_solid_angle(t, query)).sum();
        (total / (4.0 * std::f64::consts::PI)) as f32
    }

    /// Closest hit by testing every triangle (O(n); the reference for tests).
    pub fn closest_hit_brute_force(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<Hit> {
        let (origin, dir) = (Vec3A::from(origin), Vec3A::from(dir));
        let mut best_t = t_max;
        let mut best = None;
        for (slot, tri) in self.tris.iter().enumerate() {
            if let Some((t, b1, b2)) = intersect(tri, origin, dir, t_min, best_t) {
                best_t = t;
                best = Some(Hit {
                    t,
                    triangle: self.tri_index[slot],
                    b1,
                    b2,
                });
            }
        }
        best
    }

    /// Closest point by testing every triangle (O(n); the reference for tests).
    pub fn closest_point_brute_force(&self, query: Vec3) -> Option<ClosestPoint> {
        let query = Vec3A::from(query);
        let mut best: Option<ClosestPoint> = None;
        for (slot, tri) in self.tris.iter().enumerate() {
            let (point, b1, b2) = closest_on_triangle(tri, query);
            let distance = (point - query).length();
            if best.is_none_or(|b| distance < b.distance) {
                best = Some(ClosestPoint {
                    point: point.into(),
                    triangle: self.tri_index[slot],
                    b1,
                    b2,
                    distance,
                });
            }
        }
        best
    }
}

/// Picks an SAH split of `slots` (reordered in place); `None` makes a leaf.
fn sah_split(
    slots: &mut [u32],
    boxes: &[Aabb],
    centroids: &[Vec3A],
    bounds: &Aabb,
    centroid_bounds: &Aabb,
) -> Option<usize> {
    let count = slots.len();
    let extent = centroid_bounds.max - centroid_bounds.min;
    let mut best: Option<(f32, usize, usize)> = None; // (cost, axis, bins left of split)
    for axis in 0..3 {
        if extent[axis] <= 0.0 {
            continue;
        }
        let scale = BINS as f32 / extent[axis];
        let bin_of = |t: u32| {
            (((centroids[t as usize][axis] - centroid_bounds.min[axis]) * scale) as usize).min(BINS - 1)
        };
        let mut bin_box = [Aabb::EMPTY; BINS];
        let mut bin_count = [0usize; BINS];
        for &t in slots.iter() {
            let b = bin_of(t);
            bin_box[b].merge(&boxes[t as usize]);
            bin_count[b] += 1;
        }
        // Sweep from the right to get the area × count of every right part.
        let mut right_cost = [0.0f32; BINS];
        let mut acc = Aabb::EMPTY;
        let mut n = 0usize;
        for i in (1..BINS).rev() {
            acc.merge(&bin_box[i]);
            n += bin_count[i];
            right_cost[i] = if n > 0 { acc.half_area() * n as f32 } else { 0.0 };
        }
        let mut acc = Aabb::EMPTY;
        let mut n = 0usize;
        for split in 1..BINS {
            acc.merge(&bin_box[split - 1]);
            n += bin_count[split - 1];
            if n == 0 || n == count {
                continue;
            }
            let cost = acc.half_area() * n as f32 + right_cost[split];
            if best.is_none_or(|b| cost < b.0) {
                best = Some((cost, axis, split));
            }
        }
    }
    let parent_area = bounds.half_area().max(f32::MIN_POSITIVE);
    match best {
        Some((cost, axis, split)) => {
            // Relative cost: one traversal step plus the expected triangle tests.
            let split_cost = 1.0 + cost / parent_area;
            if count <= MAX_LEAF_TRIANGLES && split_cost >= count as f32 {
                return None;
            }
            let scale = BINS as f32 / extent[axis];
            let min = centroid_bounds.min[axis];
            let left = partition(slots, |t| {
                ((((centroids[t as usize][axis] - min) * scale) as usize).min(BINS - 1)) < split
            });
            Some(left)
        }
        // All centroids coincide: split by count if the leaf would be too big.
        None => (count > MAX_LEAF_TRIANGLES).then_some(count / 2),
    }
}

/// Object-median split along the widest centroid axis.
fn median_split(slots: &mut [u32], centroids: &[Vec3A], centroid_bounds: &Aabb) -> Option<usize> {
    if slots.len() <= MAX_LEAF_TRIANGLES {
        return None;
    }
    let extent = centroid_bounds.max - centroid_bounds.min;
    let axis = if extent.x >= extent.y && extent.x >= extent.z {
        0
    } else if extent.y >= extent.z {
        1
    } else {
        2
    };
    let mid = slots.len() / 2;
    slots.select_nth_unstable_by(mid, |&a, &b| {
        centroids[a as usize][axis].total_cmp(&centroids[b as usize][axis])
    });
    Some(mid)
}

/// Reorders `slots` so those satisfying `left` come first; returns their count.
fn partition(slots: &mut [u32], left: impl Fn(u32) -> bool) -> usize {
    let mut i = 0;
    for j in 0..slots.len() {
        if left(slots[j]) {
            slots.swap(i, j);
            i += 1;
        }
    }
    i
}

/// Entry distance of the ray into the node's box within `[t_min, t_max]`, if any.
/// Zero direction components give infinite reciprocals; NaNs from `0 · ∞` are
/// ignored by `min`/`max`, which keeps the test conservative.
#[inline]
fn slab(node: &Node, origin: Vec3A, inv: Vec3A, t_min: f32, t_max: f32) -> Option<f32> {
    let t0 = (node.min - origin) * inv;
    let t1 = (node.max - origin) * inv;
    let enter = t0.min(t1).max_element().max(t_min);
    let exit = t0.max(t1).min_element().min(t_max);
    (enter <= exit).then_some(enter)
}

/// Möller–Trumbore: `(t, b1, b2)` if the ray hits the triangle with `t ∈ [t_min, t_max]`.
#[inline]
fn intersect(tri: &Tri, origin: Vec3A, dir: Vec3A, t_min: f32, t_max: f32) -> Option<(f32, f32, f32)> {
    let p = dir.cross(tri.e2);
    let det = tri.e1.dot(p);
    if det == 0.0 {
        return None;
    }
    let inv_det = 1.0 / det;
    let s = origin - tri.a;
    let b1 = s.dot(p) * inv_det;
    if !(0.0..=1.0).contains(&b1) {
        return None;
    }
    let q = s.cross(tri.e1);
    let b2 = dir.dot(q) * inv_det;
    if b2 < 0.0 || b1 + b2 > 1.0 {
        return None;
    }
    let t = tri.e2.dot(q) * inv_det;
    (t >= t_min && t <= t_max).then_some((t, b1, b2))
}

/// Squared distance from `p` to the node's box (0 inside).
#[inline]
fn box_distance2(node: &Node, p: Vec3A) -> f32 {
    let d = (node.min - p).max(p - node.max).max(Vec3A::ZERO);
    d.length_squared()
}

/// The closest point to `query` on the triangle with `corners`, and its barycentric
/// weights `(b1, b2)` of the second and third corners.
pub fn closest_point_on_triangle(corners: [Vec3; 3], query: Vec3) -> (Vec3, f32, f32) {
    let a = Vec3A::from(corners[0]);
    let tri = Tri {
        a,
        e1: Vec3A::from(corners[1]) - a,
        e2: Vec3A::from(corners[2]) - a,
    };
    let (point, b1, b2) = closest_on_triangle(&tri, Vec3A::from(query));
    (point.into(), b1, b2)
}

/// Closest point on a triangle to `p` and its barycentric weights `(b1, b2)` of the
/// second and third corners, by the Voronoi region of `p`.
fn closest_on_triangle(tri: &Tri, p: Vec3A) -> (Vec3A, f32, f32) {
    let (a, ab, ac) = (tri.a, tri.e1, tri.e2);
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, 0.0, 0.0);
    }
    let bp = p - (a + ab);
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return (a + ab, 1.0, 0.0);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + v * ab, v, 0.0);
    }
    let cp = p - (a + ac);
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return (a + ac, 0.0, 1.0);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + w * ac, 0.0, w);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        // Edge from the second to the third corner.
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (a + ab + w * (ac - ab), 1.0 - w, w);
    }
    let denom = va + vb + vc;
    if denom.abs() <= f32::MIN_POSITIVE {
        // Degenerate (zero-area) triangle that slipped past the edge tests.
        return (a, 0.0, 0.0);
    }
    let v = vb / denom;
    let w = vc / denom;
    (a + v * ab + w * ac, v, w)
}

/// Signed solid angle subtended by a triangle at `q` (Van Oosterom & Strackee),
/// positive when `q` is behind the triangle (on the side its normal points away from).
fn triangle_solid_angle(tri: &Tri, q: Vec3A) -> f64 {
    let a = (tri.a - q).as_dvec3();
    let b = (tri.a + tri.e1 - q).as_dvec3();
    let c = (tri.a + tri.e2 - q).as_dvec3();
    let (la, lb, lc) = (a.length(), b.length(), c.length());
    let numerator = a.dot(b.cross(c));
    let denominator = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
    2.0 * numerator.atan2(denominator)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64Mcg;

    /// A UV sphere (outward CCW) with `rings × segments` quads.
    fn sphere(radius: f32, rings: u32, segments: u32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let mut p = Vec::new();
        for i in 0..=rings {
            let theta = std::f32::consts::PI * i as f32 / rings as f32;
            for j in 0..segments {
                let phi = std::f32::consts::TAU * j as f32 / segments as f32;
                p.push(radius * Vec3::new(theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin()));
            }
        }
        let mut t = Vec::new();
        let idx = |i: u32, j: u32| i * segments + j % segments;
        for i in 0..rings {
            for j in 0..segments {
                let (a, b, c, d) = (idx(i, j), idx(i, j + 1), idx(i + 1, j), idx(i + 1, j + 1));
                if i > 0 {
                    t.push([a, b, c]);
                }
                if i + 1 < rings {
                    t.push([b, d, c]);
                }
            }
        }
        (p, t)
    }

    fn soup(n: usize, rng: &mut Pcg64Mcg) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let mut p = Vec::new();
        let mut t = Vec::new();
        for i in 0..n {
            let c = Vec3::new(rng.random(), rng.random(), rng.random()) * 2.0 - 1.0;
            for _ in 0..3 {
                p.push(c + 0.2 * (Vec3::new(rng.random(), rng.random(), rng.random()) - 0.5));
            }
            let k = 3 * i as u32;
            t.push([k, k + 1, k + 2]);
        }
        (p, t)
    }

    fn random_unit(rng: &mut Pcg64Mcg) -> Vec3 {
        loop {
            let v = Vec3::new(rng.random(), rng.random(), rng.random()) * 2.0 - 1.0;
            let l = v.length_squared();
            if l > 1e-4 && l <= 1.0 {
                return v / l.sqrt();
            }
        }
    }

    #[test]
    fn rays_match_brute_force() {
        let mut rng = Pcg64Mcg::seed_from_u64(1);
        let (sp, st) = sphere(0.7, 24, 48);
        let (qp, qt) = soup(2000, &mut rng);
        for (p, t) in [(sp, st), (qp, qt)] {
            let bvh = Bvh::new(&p, &t);
            let mut hits = 0;
            for _ in 0..3000 {
                let origin = Vec3::new(rng.random(), rng.random(), rng.random()) * 3.0 - 1.5;
                let dir = random_unit(&mut rng);
                let t_max = if rng.random::<f32>() < 0.5 {
                    f32::INFINITY
                } else {
                    rng.random::<f32>() * 2.0
                };
                let fast = bvh.closest_hit(origin, dir, 0.0, t_max);
                let slow = bvh.closest_hit_brute_force(origin, dir, 0.0, t_max);
                assert_eq!(fast.is_some(), slow.is_some(), "{origin} {dir}");
                assert_eq!(bvh.any_hit(origin, dir, 0.0, t_max), slow.is_some());
                if let (Some(f), Some(s)) = (fast, slow) {
                    hits += 1;
                    assert!((f.t - s.t).abs() <= 1e-6 * s.t.max(1.0), "{f:?} {s:?}");
                    if f.triangle == s.triangle {
                        assert_eq!((f.b1, f.b2), (s.b1, s.b2));
                    } else {
                        // Only a tie (shared edge) may pick a different triangle.
                        assert!((f.t - s.t).abs() <= 1e-6);
                    }
                }
            }
            assert!(hits > 300, "too few hits to be a test: {hits}");
        }
    }

    #[test]
    fn closest_points_match_brute_force() {
        let mut rng = Pcg64Mcg::seed_from_u64(2);
        let (p, t) = soup(500, &mut rng);
        let bvh = Bvh::new(&p, &t);
        for _ in 0..500 {
            let q = Vec3::new(rng.random(), rng.random(), rng.random()) * 4.0 - 2.0;
            let fast = bvh.closest_point(q, f32::INFINITY).unwrap();
            let slow = bvh.closest_point_brute_force(q).unwrap();
            assert!((fast.distance - slow.distance).abs() <= 1e-6, "{fast:?} {slow:?}");
            // Barycentrics reproduce the point on the reported triangle.
            let [a, b, c] = t[fast.triangle as usize].map(|i| p[i as usize]);
            let recon = a + fast.b1 * (b - a) + fast.b2 * (c - a);
            assert!(recon.abs_diff_eq(fast.point, 1e-5));
            assert!(fast.b1 >= 0.0 && fast.b2 >= 0.0 && fast.b1 + fast.b2 <= 1.0 + 1e-6);
        }
        // A distance limit below the true distance finds nothing.
        let q = Vec3::splat(10.0);
        let d = bvh.closest_point(q, f32::INFINITY).unwrap().distance;
        assert!(bvh.closest_point(q, 0.99 * d).is_none());
    }

    #[test]
    fn winding_number_inside_outside() {
        let (p, t) = sphere(1.0, 32, 64);
        let bvh = Bvh::new(&p, &t);
        let mut rng = Pcg64Mcg::seed_from_u64(3);
        for _ in 0..300 {
            let q = random_unit(&mut rng) * rng.random::<f32>() * 3.0;
            let r = q.length();
            if (r - 1.0).abs() < 0.02 {
                continue;
            }
            let fast = bvh.winding_number(q);
            let exact = bvh.winding_number_exact(q);
            let want = if r < 1.0 { 1.0 } else { 0.0 };
            assert!((exact - want).abs() < 1e-3, "exact {exact} at r = {r}");
            assert!((fast - want).abs() < 0.05, "fast {fast} at r = {r}");
        }
    }

    #[test]
    fn build_is_valid_tree() {
        let mut rng = Pcg64Mcg::seed_from_u64(4);
        let (p, t) = soup(3000, &mut rng);
        let bvh = Bvh::new(&p, &t);
        // Every triangle appears once, leaves are small, boxes contain their triangles.
        let mut seen = vec![false; t.len()];
        for &i in &bvh.tri_index {
            assert!(!seen[i as usize]);
            seen[i as usize] = true;
        }
        for node in &bvh.nodes {
            if node.count > 0 {
                assert!(node.count as usize <= MAX_LEAF_TRIANGLES);
                for tri in
                    &bvh.tris[node.first_or_child as usize..(node.first_or_child + node.count) as usize]
                {
                    for v in [tri.a, tri.a + tri.e1, tri.a + tri.e2] {
                        assert!(v.cmpge(node.min - 1e-6).all() && v.cmple(node.max + 1e-6).all());
                    }
                }
            }
        }
        // Degenerate input: all triangles identical.
        let same = vec![[0u32, 1, 2]; 50];
        let bvh = Bvh::new(&[Vec3::ZERO, Vec3::X, Vec3::Y], &same);
        assert!(bvh.any_hit(Vec3::new(0.2, 0.2, 1.0), Vec3::NEG_Z, 0.0, 2.0));
        let empty = Bvh::new(&[], &[]);
        assert!(empty.closest_hit(Vec3::ZERO, Vec3::X, 0.0, 1.0).is_none());
        assert!(empty.closest_point(Vec3::ZERO, 1.0).is_none());
    }
}
