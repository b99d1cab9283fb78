//! Convex polygons in the state plane (a, b) = (ṡ², s̈): the controllable sets of the backward
//! pass. Every operation here may only shrink a set (clipping, dropping vertices), so what the
//! planner keeps is an inner approximation of the true controllable set and every state it
//! accepts can still be brought to rest.

/// `na·a + nb·b ≤ d`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HalfPlane {
    pub na: f64,
    pub nb: f64,
    pub d: f64,
}

/// A convex polygon, vertices counter-clockwise; empty when no state qualifies.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Polygon {
    pub vertices: Vec<[f64; 2]>,
}

impl Polygon {
    /// The box `a_lo ≤ a ≤ a_hi`, `b_lo ≤ b ≤ b_hi`.
    pub fn rectangle(a_lo: f64, a_hi: f64, b_lo: f64, b_hi: f64) -> Self {
        Polygon {
            vertices: vec![[a_lo, b_lo], [a_hi, b_lo], [a_hi, b_hi], [a_lo, b_hi]],
        }
    }

    pub fn is_empty(&self) -> bool {
        self.vertices.is_empty()
    }

    /// Largest |a| and |b| of a vertex: the scale of the rounding tolerances.
    pub fn extent(&self) -> (f64, f64) {
        self.vertices
            .iter()
            .fold((0.0f64, 0.0f64), |(a, b), v| (a.max(v[0].abs()), b.max(v[1].abs())))
    }

    /// Keeps the part with `h.na·a + h.nb·b ≤ h.d` (Sutherland-Hodgman on one edge).
    /// Returns whether anything was cut off.
    pub fn clip(&mut self, h: HalfPlane) -> bool {
        let n = self.vertices.len();
        if n == 0 {
            return false;
        }
        let (ea, eb) = self.extent();
        let tol = 1e-13 * (h.na.abs() * ea + h.nb.abs() * eb + h.d.abs());
        let f = |v: &[f64; 2]| h.na * v[0] + h.nb * v[1] - h.d;
        if self.vertices.iter().all(|v| f(v) <= tol) {
            return false;
        }
        // The clipped polygon goes to the end of the same buffer (a convex polygon cut by one
        // line gains at most one vertex), then replaces the old vertices: no allocation once
        // the buffer has grown.
        self.vertices.reserve(n + 1);
        for i in 0..n {
            let (p, q) = (self.vertices[i], self.vertices[(i + 1) % n]);
            let (fp, fq) = (f(&p), f(&q));
            if fp <= tol {
                self.vertices.push(p);
            }
            if (fp < -tol && fq > tol) || (fq < -tol && fp > tol) {
                let t = fp / (fp - fq);
                self.vertices.push([p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])]);
            }
        }
        self.vertices.drain(..n);
        dedup(&mut self.vertices, ea, eb);
        true
    }

    /// The edges as half-planes (outward normals).
    pub fn half_planes(&self, out: &mut Vec<HalfPlane>) {
        out.clear();
        let n = self.vertices.len();
        if n < 2 {
            // A point (or nothing): the box around it.
            if let Some(&[a, b]) = self.vertices.first() {
                out.extend([
                    HalfPlane { na: 1.0, nb: 0.0, d: a },
                    HalfPlane {
                        na: -1.0,
                        nb: 0.0,
                        d: -a,
                    },
                    HalfPlane { na: 0.0, nb: 1.0, d: b },
                    HalfPlane {
                        na: 0.0,
                        nb: -1.0,
                        d: -b,
                    },
                ]);
            }
            return;
        }
        for i in 0..n {
            let (p, q) = (self.vertices[i], self.vertices[(i + 1) % n]);
            let (na, nb) = (q[1] - p[1], p[0] - q[0]);
            if na == 0.0 && nb == 0.0 {
                continue;
            }
            out.push(HalfPlane {
                na,
                nb,
                d: na * p[0] + nb * p[1],
            });
        }
    }

    /// Whether `(a, b)` lies inside, to a relative tolerance.
    pub fn contains(&self, a: f64, b: f64, rel: f64) -> bool {
        let n = self.vertices.len();
        match n {
            0 => false,
            1 => {
                let v = self.vertices[0];
                (a - v[0]).abs() <= rel * (1.0 + v[0].abs()) && (b - v[1]).abs() <= rel * (1.0 + v[1].abs())
            }
            _ => {
                let (ea, eb) = self.extent();
                (0..n).all(|i| {
                    let (p, q) = (self.vertices[i], self.vertices[(i + 1) % n]);
                    let (na, nb) = (q[1] - p[1], p[0] - q[0]);
                    na * (a - p[0]) + nb * (b - p[1]) <= rel * (na.abs() * ea.max(a.abs()) + nb.abs() * eb.max(b.abs()))
                })
            }
        }
    }

    /// Drops vertices until at most `max` are left, each time the one whose removal loses the
    /// least area (an inner approximation: the polygon only shrinks; vertices on the chord of
    /// their neighbours go first). Vertices at rest (a = 0) stay.
    pub fn simplify(&mut self, max: usize) {
        let v = &mut self.vertices;
        if v.len() <= max.max(3) {
            return;
        }
        let area = |v: &Vec<[f64; 2]>, i: usize| {
            let n = v.len();
            let (p, q, r) = (v[(i + n - 1) % n], v[i], v[(i + 1) % n]);
            ((q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])).abs()
        };
        // The rest edge (a = 0) stays whole: a state at rest must stay controllable.
        let ea = v.iter().fold(0.0f64, |m, p| m.max(p[0].abs()));
        let keep = |p: &[f64; 2]| p[0] <= 1e-12 * ea;
        while v.len() > max.max(3) {
            let (mut best, mut least) = (usize::MAX, f64::INFINITY);
            for i in 0..v.len() {
                if keep(&v[i]) {
                    continue;
                }
                let a = area(v, i);
                if a < least {
                    least = a;
                    best = i;
                }
            }
            if best == usize::MAX {
                break;
            }
            v.remove(best);
        }
    }

    /// Grows the polygon to the convex hull of itself and `x` (a point of a convex set that
    /// holds the polygon too, so that the hull stays inside that set).
    pub fn include(&mut self, x: [f64; 2]) {
        let v = &self.vertices;
        let n = v.len();
        if n < 3 {
            return;
        }
        // Edge i (v[i] to v[i + 1], counter-clockwise) sees x when x lies to its right.
        let sees = |i: usize| {
            let (p, q) = (v[i], v[(i + 1) % n]);
            (q[0] - p[0]) * (x[1] - p[1]) - (q[1] - p[1]) * (x[0] - p[0]) < 0.0
        };
        let visible: Vec<bool> = (0..n).map(sees).collect();
        let Some(first) = (0..n).find(|&i| visible[i] && !visible[(i + n - 1) % n]) else {
            return;
        };
        // The chain of edges that see x, from `first` to `last`: the vertices between them go,
        // x comes in their place.
        let mut last = first;
        while visible[(last + 1) % n] && (last + 1) % n != first {
            last = (last + 1) % n;
        }
        let mut out = Vec::with_capacity(n + 1);
        out.push(v[first]);
        out.push(x);
        let mut i = (last + 1) % n;
        while i != first {
            out.push(v[i]);
            i = (i + 1) % n;
        }
        self.vertices = out;
    }

    /// The vertex furthest along the direction `(na, nb)`.
    pub fn max_along(&self, na: f64, nb: f64) -> Option<[f64; 2]> {
        self.vertices
            .iter()
            .copied()
            .max_by(|p, q| (na * p[0] + nb * p[1]).total_cmp(&(na * q[0] + nb * q[1])))
    }
}

/// Removes consecutive (and first-last) vertices closer than rounding.
fn dedup(v: &mut Vec<[f64; 2]>, ea: f64, eb: f64) {
    let close = |p: &[f64; 2], q: &[f64; 2]| (p[0] - q[0]).abs() <= 1e-14 * ea && (p[1] - q[1]).abs() <= 1e-14 * eb;
    v.dedup_by(|q, p| close(p, q));
    while v.len() > 1 && close(&v[0], &v[v.len() - 1]) {
        v.pop();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clipping_a_square_by_its_diagonal_leaves_a_triangle() {
        let mut p = Polygon::rectangle(0.0, 1.0, 0.0, 1.0);
        assert!(p.clip(HalfPlane {
            na: 1.0,
            nb: 1.0,
            d: 1.0
        }));
        assert_eq!(p.vertices.len(), 3);
        assert!(p.contains(0.2, 0.2, 1e-12));
        assert!(!p.contains(0.8, 0.8, 1e-12));
        // A constraint that cuts nothing leaves it as it is.
        assert!(!p.clip(HalfPlane {
            na: 1.0,
            nb: 0.0,
            d: 2.0
        }));
        assert!(p.clip(HalfPlane {
            na: 1.0,
            nb: 0.0,
            d: -1.0
        }));
        assert!(p.is_empty());
    }

    #[test]
    fn including_a_point_gives_the_hull() {
        let mut p = Polygon::rectangle(0.0, 1.0, 0.0, 1.0);
        p.include([2.0, 0.5]);
        assert_eq!(p.vertices.len(), 5);
        assert!(p.contains(2.0, 0.5, 1e-12));
        assert!(p.contains(1.5, 0.5, 1e-12));
        assert!(!p.contains(1.5, 0.9, 1e-12));
        // Beyond a corner: the corner goes, the point takes its place.
        let mut q = Polygon::rectangle(0.0, 1.0, 0.0, 1.0);
        q.include([3.0, 3.0]);
        assert_eq!(q.vertices.len(), 4);
        assert!(q.vertices.contains(&[3.0, 3.0]));
        assert!(!q.vertices.contains(&[1.0, 1.0]));
        // A point inside changes nothing.
        let mut r = Polygon::rectangle(0.0, 1.0, 0.0, 1.0);
        r.include([0.5, 0.5]);
        assert_eq!(r.vertices.len(), 4);
    }

    #[test]
    fn simplifying_only_shrinks() {
        let mut p = Polygon::default();
        for i in 0..40 {
            let t = i as f64 / 40.0 * std::f64::consts::TAU;
            // States live in a >= 0; the vertex at t = pi touches rest (a = 0).
            p.vertices.push([1.0 + t.cos(), t.sin()]);
        }
        let before = p.clone();
        p.simplify(8);
        assert_eq!(p.vertices.len(), 8);
        assert!(p.vertices.iter().any(|v| v[0] == 0.0), "the rest vertex stays");
        for v in &p.vertices {
            assert!(before.contains(v[0], v[1], 1e-12));
        }
        let mut hp = Vec::new();
        p.half_planes(&mut hp);
        assert_eq!(hp.len(), 8);
        for h in &hp {
            for v in &p.vertices {
                assert!(h.na * v[0] + h.nb * v[1] <= h.d + 1e-12);
            }
        }
    }
}
