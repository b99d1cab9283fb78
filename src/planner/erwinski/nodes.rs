//! Segment boundaries (nodes) of the Erwinski planner, Erwinski et al. 2022 section III steps 1-4, produced
//! lazily from the front of the path so that planning can start before the path is scanned.
//!
//! Per path element: the FLF scan (step 1) and its critical points (steps 2-3), the knots where
//! the curve is only C0/C1 and the element joins become nodes; a speed-cap dip between two nodes
//! becomes a node; the look-ahead sets each node's feed and drops the critical points that
//! reachability binds (step 4). All of it runs on a window that grows one control point's worth
//! of scan samples at a time, and a node is handed out (committed) only when nothing beyond the
//! window can change it:
//! - scan samples, arc lengths and the arc-length grid are the same whether taken early or
//!   late, and a critical point is final once the search has judged its neighbours;
//! - the look-ahead drops, round after round, every critical point whose feed reachability
//!   binds, on the feeds of the round before. What lies beyond the window reaches a window node
//!   only through the backward pass. A node `h` whose own cap holds in the backward pass even
//!   with the window's far end at rest and every window node present (the most any
//!   continuation can ask: dropping nodes and a faster far end only relax it) cuts that chain:
//!   the nodes before it, and its own feed in every round, depend on the window alone. If `h`
//!   also survives every round, the nodes up to it are committed with the rounds run on them
//!   alone, and the next window starts each round from `h`'s feed in that round, as the
//!   whole-path computation would.
//!
//! The nodes only steer the segment solver; whatever it emits is checked by finite differences.

use super::flf::{flf, CriticalPoint, CriticalPointSearch, FlfScan};
use super::quick_check::ArcGrid;
use super::scan_ahead::{ScanAhead, Scanned};
use super::scurve_fit::reachable_feed;
use super::tuning::*;
use super::{PlanOptions, PlanStart, FEED_HEADROOM};
use crate::geometry::{ArcLengthTable, Nurbs, PathElement};
use crate::planner::window::Window;
use crate::planner::{Limits, PathCurves};
use nurbs_rtcore::interpolator::Derivs;
use nurbs_rtcore::math::{dot, norm, sub};
use nurbs_rtcore::CurveView;
use std::collections::VecDeque;

/// A segment boundary: where the previous segment ends and the next begins (the same point;
/// at a join of two path elements the curve changes).
#[derive(Clone, Copy, Debug)]
pub(super) struct Node {
    /// Parameter and arc length where the segment ending here ends (on the curve the previous
    /// node's segment starts on).
    pub end_u: f64,
    pub end_s: f64,
    /// Curve and parameter of the segment starting here.
    pub start_curve: usize,
    pub start_u: f64,
    pub start_s: f64,
    /// Feed cap at this point.
    pub cap: f64,
    /// Path start/end, element joins, corners and dips: never merged away.
    pub hard: bool,
}

impl Node {
    /// A hard node inside curve `c` at parameter `u`, arc length `s`, with feed cap `cap`.
    pub fn within(c: usize, u: f64, s: f64, cap: f64) -> Node {
        Node {
            end_u: u,
            end_s: s,
            start_curve: c,
            start_u: u,
            start_s: s,
            cap,
            hard: true,
        }
    }
}

/// A committed node with its look-ahead feed (the end feed its segment aims for).
#[derive(Clone, Copy, Debug)]
pub(super) struct Boundary {
    pub node: Node,
    pub feed: f64,
    /// The end of the path (the last node).
    pub path_end: bool,
}

/// One path element as far as it has been scanned.
pub(super) struct ElementScan {
    /// The planning limits with the element's programmed feed.
    limits: Limits,
    scan: FlfScan,
    /// Arc-length derivatives at the scan parameters (for the quick estimate).
    pub grid: ArcGrid,
    pub table: ArcLengthTable,
    search: CriticalPointSearch,
    /// Critical points and C0/C1 knots (with their fixed caps) not yet turned into nodes.
    found: VecDeque<CriticalPoint>,
    breaks: VecDeque<(f64, f64)>,
    /// Every C0/C1 knot: a critical point this close to one is superseded by it.
    all_breaks: Vec<f64>,
    /// The scan's samples and arc-length table as the helper thread computed them, if it did.
    scanned: Option<Scanned>,
}

impl ElementScan {
    /// Extends the arc-length table beyond parameter `t` of `curve` (this element's).
    fn table_past(&mut self, curve: &Nurbs, t: f64) {
        match &self.scanned {
            Some(scanned) => self.table.extend_past_from(&scanned.table, t),
            None => self.table.extend_past(curve, t),
        }
    }
}

/// The planning limits of `element`: `planning` with the element's programmed feed.
pub(super) fn element_limits(planning: &Limits, element: &PathElement, feed_override: f64) -> Limits {
    let mut limits = planning.clone();
    if let Some(f) = element.feed {
        limits.feed = limits.feed.min(f * feed_override * (1.0 - FEED_HEADROOM));
    }
    limits
}

/// The lazily produced, committed nodes of a path.
pub(super) struct NodeStream {
    planning: Limits,
    options: PlanOptions,
    start: PlanStart,
    tip: usize,
    /// Nominal tangential acceleration and jerk of the look-ahead.
    accel: f64,
    jerk: f64,
    /// Per element from the start element on, as far as the scan has reached, the front
    /// released once the planner no longer needs it ([`NodeStream::release_elements_before`]).
    elements: Window<ElementScan>,
    /// Element being scanned; `elements.len()` once every node is produced.
    current: usize,
    /// Produced nodes not yet committed, after the last committed one (`window[0]`), whose
    /// look-ahead feed in each round of merging is `window_feeds` (the last one for later
    /// rounds).
    window: Vec<Node>,
    window_feeds: Vec<f64>,
    /// Window length at which to try committing again (after a try that committed nothing,
    /// a quarter more: each try costs the window's length).
    commit_at: usize,
    /// Committed nodes not yet taken.
    ready: VecDeque<Boundary>,
    /// Critical points and breaks per element, in path order (for the plan's report).
    pub criticals: Vec<(usize, CriticalPoint)>,
    /// Every node of the path has been produced.
    exhausted: bool,
    /// Scans of the elements ahead from the helper thread.
    ahead: ScanAhead,
}

impl NodeStream {
    /// The nodes of `curves` from `start` on; the unread rest of a streamed path is read and
    /// scanned ahead in a helper thread ([`ScanAhead`]).
    pub fn new(curves: &mut PathCurves, tip: usize, planning: Limits, options: &PlanOptions, start: PlanStart) -> Self {
        let (accel, jerk) = (planning.min_accel(), planning.min_jerk());
        let of_element = planning.clone();
        let feed_override = options.feed_override;
        let ahead = ScanAhead::start(curves, tip, options.samples_per_control_point, move |e| {
            element_limits(&of_element, e, feed_override)
        });
        // A plan from a motion in progress starts at its feed, not at rest.
        let start_feed = options.moving.map_or(0.0, |m| m.feed);
        NodeStream {
            tip,
            accel,
            jerk,
            elements: Window::starting_at(start.curve),
            current: start.curve,
            planning,
            options: options.clone(),
            start,
            window: Vec::new(),
            window_feeds: vec![start_feed],
            commit_at: 0,
            ready: VecDeque::new(),
            criticals: Vec::new(),
            exhausted: false,
            ahead,
        }
    }

    /// The scan of element `c` (reached by the committed nodes on it).
    pub fn element(&self, c: usize) -> &ElementScan {
        &self.elements[c]
    }

    /// Forgets the scans of the elements before `c` (no segment before it is planned again).
    pub fn release_elements_before(&mut self, c: usize) {
        self.elements.release_before(c.min(self.current));
    }

    /// Elements scanned to their end: their critical points in [`NodeStream::criticals`] are
    /// final.
    pub fn scanned_elements(&self) -> usize {
        self.current
    }

    /// Whether every node of the path has been produced (the whole path scanned).
    pub fn is_exhausted(&self) -> bool {
        self.exhausted
    }

    /// The next committed node, scanning (and reading the path) as far as that needs; `None`
    /// after the path end.
    pub fn next(&mut self, curves: &mut PathCurves) -> Option<Boundary> {
        while self.ready.is_empty() && !self.is_exhausted() {
            self.advance(curves);
            if self.window.len() >= self.commit_at || self.is_exhausted() {
                self.commit();
            }
        }
        self.ready.pop_front()
    }

    /// Scans one control point's worth of samples further and produces the nodes that settles.
    fn advance(&mut self, curves: &mut PathCurves) {
        let c = self.current;
        if !curves.load(c) {
            // Only where a streamed path ends early (its file failed): there is nothing to scan.
            self.exhausted = true;
            return;
        }
        // The join after this element needs the next one.
        let last = !curves.load(c + 1);
        let curves = &*curves;
        let view = &curves.view(c);
        let curve = &curves.element(c).curve;
        if self.elements.len() == c {
            self.begin_element(c, curves);
        }
        let (tip, count) = (self.tip, self.options.samples_per_control_point);
        let e = &mut self.elements[c];
        let grid = &mut e.grid;
        let each = &mut |u, x: &_, speed| grid.push(u, x, speed);
        let (points, settled) = match &mut e.scanned {
            Some(scanned) => {
                e.scan.extend_from(&scanned.samples, count, each);
                scanned.next_chunk()
            }
            None => {
                e.scan.extend(view, tip, &e.limits, count, each);
                let mut points = Vec::new();
                e.search.advance(view, tip, &e.limits, &e.scan, &mut points);
                (points, e.search.settled_below(&e.scan))
            }
        };
        let (u0, u1) = (view.u_min(), view.u_max());
        let near_break = |p: &CriticalPoint| e.all_breaks.iter().any(|&b| (b - p.u).abs() <= 1e-9 * (u1 - u0));
        // Critical points too close to a break are superseded by it; on the start element only
        // what lies ahead of the start point (a stop itself) counts.
        let ahead = |u: f64| c != self.start.curve || u > self.start.u + 1e-9 * (u1 - u0);
        let kept: Vec<CriticalPoint> = points.into_iter().filter(|p| !near_break(p) && ahead(p.u)).collect();
        e.found.extend(kept);
        // Critical points and breaks in order of `u`, as far as no later critical point can
        // come before them (a critical point first at equal `u`).
        loop {
            let e = &mut self.elements[c];
            let point = e.found.front().copied();
            let brk = e.breaks.front().copied();
            let (p, fixed_cap) = match (point, brk) {
                (Some(p), Some((b, _))) if p.u <= b => (p, None),
                (_, Some((b, cap))) => (CriticalPoint { u: b, flf: cap }, Some(cap)),
                (Some(p), None) => (p, None),
                (None, None) => break,
            };
            if p.u >= settled {
                break;
            }
            match fixed_cap {
                Some(_) => e.breaks.pop_front(),
                None => e.found.pop_front().map(|p| (p.u, p.flf)),
            };
            e.table_past(curve, p.u);
            let s = e.table.length_to(curve, p.u);
            let cap = fixed_cap.unwrap_or_else(|| {
                let v = flf(view, tip, &e.limits, p.u);
                v.speed_cap().min(self.options.flf_margin * v.accel.min(v.jerk))
            });
            self.criticals.push((c, p));
            self.push_node(
                Node {
                    hard: fixed_cap.is_some(),
                    ..Node::within(c, p.u, s, cap)
                },
                curves,
            );
        }
        let e = &mut self.elements[c];
        if e.scan.is_complete() {
            e.table_past(curve, f64::INFINITY);
            let s1 = e.table.total();
            let next = c + 1;
            let node = if last {
                Node::within(c, u1, s1, 0.0)
            } else {
                // The join: the next element starts here.
                Node {
                    end_u: u1,
                    end_s: s1,
                    start_curve: next,
                    start_u: curves.view(next).u_min(),
                    start_s: 0.0,
                    cap: join_cap(curves, &self.planning, next),
                    hard: true,
                }
            };
            self.push_node(node, curves);
            self.current = next;
            self.exhausted = last;
        }
    }

    /// Sets up the scan of element `c`; on the start element, the start node.
    fn begin_element(&mut self, c: usize, curves: &PathCurves) {
        let view = &curves.view(c);
        let limits = element_limits(&self.planning, curves.element(c), self.options.feed_override);
        let (u0, u1) = (view.u_min(), view.u_max());
        let all_breaks = interior_breaks(view, self.tip, &limits);
        let breaks = all_breaks
            .iter()
            .copied()
            .filter(|&(u, _)| c != self.start.curve || u > self.start.u + 1e-9 * (u1 - u0))
            .collect();
        self.elements.push(ElementScan {
            scan: FlfScan::lazy(view, self.options.samples_per_control_point),
            grid: ArcGrid::empty(self.tip),
            table: ArcLengthTable::lazy(&curves.element(c).curve),
            search: CriticalPointSearch::default(),
            found: VecDeque::new(),
            breaks,
            all_breaks: all_breaks.into_iter().map(|(u, _)| u).collect(),
            limits,
            scanned: self.ahead.take(c),
        });
        if c == self.start.curve {
            // The start: at rest (or at the feed of the motion continued), committed at once.
            let PlanStart { u, s, .. } = self.start;
            let feed = self.window_feeds[0];
            let node = Node::within(c, u, s, feed);
            self.window.push(node);
            self.ready.push_back(Boundary {
                node,
                feed,
                path_end: false,
            });
        }
    }

    /// Appends a produced node; a speed-cap dip below both ends of the segment before it
    /// becomes a node too (any other dip is left to the exact check of the segment, which
    /// splits it there if the profile passes it too fast).
    fn push_node(&mut self, node: Node, curves: &PathCurves) {
        self.window.push(node);
        let mut k = self.window.len() - 2;
        while k + 1 < self.window.len() {
            let (a, b) = (self.window[k], self.window[k + 1]);
            let c = a.start_curve;
            let e = &self.elements[c];
            match e.scan.min_speed_cap_between(a.start_u, b.end_u) {
                Some((m, u)) if m < a.cap.min(b.cap) && u > a.start_u && u < b.end_u => {
                    let s = e.table.length_to(&curves.element(c).curve, u);
                    self.window.insert(k + 1, Node::within(c, u, s, m));
                }
                _ => k += 1,
            }
        }
    }

    /// Commits the leading nodes of the window that nothing beyond it can change.
    fn commit(&mut self) {
        if self.window.len() < 2 {
            return;
        }
        if self.is_exhausted() {
            let rounds = self.settle(self.window.len());
            self.hand_out(&rounds, self.window.len() - 1, true);
            return;
        }
        // From the far end back to the first node that cuts the backward chain and survives.
        let last = self.window.len() - 1;
        let reachable = self.forward_highest();
        let mut lowest = 0.0;
        for h in (1..last).rev() {
            let node = self.window[h];
            lowest = self.backward_lowest(h, lowest);
            // A node the forward pass cannot bring to its cap is dropped in the first round (a
            // quick filter: the rounds below decide).
            if lowest < node.cap || (!node.hard && reachable[h] < MERGE_TOLERANCE * node.cap) {
                continue;
            }
            let rounds = self.settle(h + 1);
            let survives = |r: &Vec<Option<f64>>| r[h].is_some_and(|f| node.hard || f >= MERGE_TOLERANCE * node.cap);
            if rounds.iter().all(survives) {
                self.hand_out(&rounds, h, false);
                self.commit_at = 0;
                return;
            }
        }
        self.commit_at = self.window.len() + self.window.len() / 4 + 1;
    }

    /// Commits the window nodes up to `q` kept in the last of `rounds`; `q` starts the window.
    fn hand_out(&mut self, rounds: &[Vec<Option<f64>>], q: usize, path_end: bool) {
        let last = &rounds[rounds.len() - 1];
        for i in 1..=q {
            if let Some(feed) = last[i] {
                self.ready.push_back(Boundary {
                    node: self.window[i],
                    feed,
                    path_end: path_end && i == q,
                });
            }
        }
        self.window_feeds = rounds.iter().map(|r| r[q].expect("kept in every round")).collect();
        self.window.drain(..q);
    }

    /// The lowest feed the backward pass can give window node `k`, whatever lies beyond the
    /// far end and whichever window nodes are dropped, from that of its successor. Reachability
    /// of a symmetric ramp is not monotone in the feed reached (a ramp from rest covers less
    /// distance than one from a low feed), so it is the least over the feeds the successor may
    /// get: between its lowest and the feed reachable from that (from higher ones, more is
    /// reachable), sampled.
    fn backward_lowest(&self, k: usize, successor_lowest: f64) -> f64 {
        let length = (self.window[k + 1].end_s - self.window[k].start_s).max(0.0);
        let cap = self.window[k].cap;
        let reach = |v: f64| reachable_feed(v, length, self.accel, self.jerk, cap);
        let (from, to) = (successor_lowest, reach(successor_lowest));
        (0..=SUCCESSOR_FEEDS)
            .map(|i| reach(from + (to - from) * i as f64 / SUCCESSOR_FEEDS as f64))
            .fold(cap.min(to), f64::min)
    }

    /// Feeds of the window nodes by forward reachability alone (no node dropped).
    fn forward_highest(&self) -> Vec<f64> {
        let nodes = &self.window;
        let mut feeds = vec![self.window_feeds[0]; nodes.len()];
        for k in 0..nodes.len() - 1 {
            let length = (nodes[k + 1].end_s - nodes[k].start_s).max(0.0);
            let cap = nodes[k + 1].cap;
            feeds[k + 1] = cap.min(reachable_feed(feeds[k], length, self.accel, self.jerk, cap));
        }
        feeds
    }

    /// Look-ahead and step 4 on the first `len` window nodes, the last one at its cap, in
    /// rounds: the node feeds by reachability, then every critical point whose feed
    /// reachability binds (the segments around it are too short to reach its cap) is dropped
    /// and its segments merged, until none is. Returns per round the feed of each of those
    /// nodes (`None`: dropped before).
    fn settle(&self, len: usize) -> Vec<Vec<Option<f64>>> {
        let mut kept: Vec<usize> = (0..len).collect();
        let mut rounds = Vec::new();
        loop {
            let nodes: Vec<Node> = kept.iter().map(|&i| self.window[i]).collect();
            let lengths: Vec<f64> = nodes.windows(2).map(|w| (w[1].end_s - w[0].start_s).max(0.0)).collect();
            let first = self.window_feeds[rounds.len().min(self.window_feeds.len() - 1)];
            let feeds = self.look_ahead(&nodes, &lengths, first);
            let mut round = vec![None; len];
            for (&i, &f) in kept.iter().zip(&feeds) {
                round[i] = Some(f);
            }
            rounds.push(round);
            let last = nodes.len() - 1;
            let before = kept.len();
            let mut j = 0;
            kept.retain(|_| {
                let n = &nodes[j];
                // The committed node and the far end stay (the caller checks the far end).
                let keep = j == 0 || j == last || n.hard || feeds[j] >= MERGE_TOLERANCE * n.cap;
                j += 1;
                keep
            });
            if kept.len() == before {
                return rounds;
            }
        }
    }

    /// Backward and forward reachability of the node feeds with the nominal tangential limits,
    /// from the committed feed `first` of `nodes[0]`.
    fn look_ahead(&self, nodes: &[Node], lengths: &[f64], first: f64) -> Vec<f64> {
        let (accel, jerk) = (self.accel, self.jerk);
        let mut feeds: Vec<f64> = nodes.iter().map(|n| n.cap).collect();
        feeds[0] = first;
        for k in (1..lengths.len()).rev() {
            feeds[k] = feeds[k].min(reachable_feed(feeds[k + 1], lengths[k], accel, jerk, feeds[k]));
        }
        for k in 0..lengths.len() {
            feeds[k + 1] = feeds[k + 1].min(reachable_feed(feeds[k], lengths[k], accel, jerk, feeds[k + 1]));
        }
        feeds
    }
}

/// Interior knots of multiplicity >= degree - 1 (continuity C1 or less) with the feed cap
/// there: zero where the tangent turns, else the curvature-jump cap of [`jump_cap`].
fn interior_breaks(view: &CurveView, tip: usize, limits: &Limits) -> Vec<(f64, f64)> {
    let p = view.degree();
    let knots = view.knots();
    let n = view.control_point_count();
    let mut out = Vec::new();
    let mut i = p + 1;
    while i < n {
        let mut m = 1;
        while i + m < n && knots[i + m] == knots[i] {
            m += 1;
        }
        if m + 1 >= p {
            let u = knots[i];
            let left = view.derivatives_left(u, 3);
            let right = view.derivatives(u, 3);
            out.push((u, jump_cap(&left, &right, tip, limits)));
        }
        i += m;
    }
    out
}

/// Feed cap across a point where the derivatives jump from `left` to `right` (parameter
/// derivatives; converted to arc length here): zero at a tangent break, otherwise the axial
/// acceleration jump at feed v, |dx''| v^2, must stay within one period's jerk.
fn jump_cap(left: &Derivs, right: &Derivs, tip: usize, limits: &Limits) -> f64 {
    let to_arc = |d: &Derivs| {
        let g2 = dot(&d[1], &d[1], tip);
        let g = g2.sqrt();
        let mut x1 = [0.0; nurbs_rtcore::MAX_DIM];
        let mut x2 = [0.0; nurbs_rtcore::MAX_DIM];
        if g > 0.0 {
            let c12 = dot(&d[1], &d[2], tip);
            for i in 0..tip {
                x1[i] = d[1][i] / g;
                x2[i] = d[2][i] / g2 - d[1][i] * c12 / (g2 * g2);
            }
        }
        (x1, x2, g)
    };
    let (l1, l2, gl) = to_arc(left);
    let (r1, r2, gr) = to_arc(right);
    let gap = norm(&sub(&left[0], &right[0]), tip);
    if gap > 1e-9 || gl == 0.0 || gr == 0.0 || dot(&l1, &r1, tip) < 1.0 - 1e-12 {
        return 0.0;
    }
    let mut cap = limits.feed;
    for i in 0..tip {
        let jump = (l2[i] - r2[i]).abs();
        if jump > 0.0 {
            cap = cap.min(0.5 * (limits.jerk[i] * limits.period / jump).sqrt());
        }
    }
    cap
}

/// Feed cap where curve `c - 1` joins curve `c`: zero at a tangent break; otherwise the axial
/// acceleration jump between the two curves must not exceed one period's jerk.
fn join_cap(curves: &PathCurves, limits: &Limits, c: usize) -> f64 {
    let (a, b) = (curves.view(c - 1), curves.view(c));
    jump_cap(
        &a.derivatives(a.u_max(), 3),
        &b.derivatives(b.u_min(), 3),
        limits.velocity.len(),
        limits,
    )
}
