//! One motion into the channel ([`Streamer`]): curves into the geometry stream, groups of
//! slots into the ring within the time margin, splices of re-plans, the start rule.

use super::*;

/// Why a plan's events stopped before its end: a panic in the planning thread (its message kept
/// by `nurbs_motion::panics`).
fn planner_thread_ended() -> String {
    let why = nurbs_motion::panics::take_last();
    format!(
        "the planner thread ended before the plan did{}",
        why.map_or(String::new(), |w| format!(": {w}"))
    )
}

/// Streams one motion into the channel: its curves into the geometry stream, its groups of
/// slots into the ring within the time margin.
pub struct Streamer<'a> {
    channel: &'a Channel,
    writer: GeometryWriter<'a>,
    /// Curves the groups taken so far need that wait for the geometry stream, from the
    /// writer's next curve on; the index the next curve queued will have.
    curves: VecDeque<Nurbs>,
    next_queued: u32,
    source: Source,
    /// The next group to go out (its curves published as far as there was room).
    current: Option<Group>,
    /// Motion time of the slots pushed and not yet taken by the module, oldest first, and
    /// their sum; slots pushed in all, and the motion time they make.
    in_ring: VecDeque<(u64, f64)>,
    buffered: f64,
    /// The ring's count of this stream's first slot (slot `k` has count `ring_base + k`).
    ring_base: u32,
    /// Slots (numbers) that end a group still in the ring or running, with where they leave
    /// the motion: where a re-plan at another feed override may join.
    group_ends: VecDeque<(u64, Box<GroupEnd>)>,
    /// The segment groups still in the ring or running: where such a re-plan may cut in.
    ring_groups: VecDeque<RingGroup>,
    pub pushed: u64,
    pub pushed_time: f64,
    /// Motion time planned (received from the planner), in how many groups, and when
    /// planning began.
    planned: f64,
    groups_planned: usize,
    began: Instant,
    margin: f64,
    /// Records may go into the ring (the start rule has held once).
    started: bool,
    /// Longest group sent (s of motion: how long a hold may take to begin).
    pub longest_group: f64,
    /// Plans at another feed override run into: at a group end in the ring (the module
    /// dropping the old plan's slots after it), and at the end of the slots sent.
    pub joins_in_ring: u32,
    pub joins_at_end: u32,
    /// ... and cutting into a record the module runs or has queued ([`crate::cut`]).
    pub cuts: u32,
    /// Where the last group sent leaves the motion (`None` before the first, and after the
    /// path's last).
    last_end: Option<Box<GroupEnd>>,
}

impl<'a> Streamer<'a> {
    /// Begins the geometry stream of a motion of a `tip`-axis path whose first curve is
    /// `first_curve` (the module must run no motion), to be filled from `source` keeping
    /// `margin` seconds queued. `began`: when its planning began (the start rule's pace).
    pub fn new(
        channel: &'a Channel,
        tip: usize,
        source: Source,
        first_curve: usize,
        margin: f64,
        began: Instant,
    ) -> Result<Self, String> {
        let first = u32::try_from(first_curve).map_err(|_| "path element index beyond 32 bits".to_string())?;
        let writer = GeometryWriter::begin(channel, first, tip, source.period())?;
        channel.set_planned_time(0.0);
        // No motion runs, so no join of an earlier stream is open.
        channel.splice.reset();
        Ok(Streamer {
            channel,
            writer,
            curves: VecDeque::new(),
            next_queued: first,
            planned: source.planned(),
            // (A source planned whole counts as paced: it has all its motion.)
            groups_planned: 0,
            source,
            current: None,
            in_ring: VecDeque::new(),
            ring_base: channel.segments.producer().pushed(),
            group_ends: VecDeque::new(),
            ring_groups: VecDeque::new(),
            buffered: 0.0,
            pushed: 0,
            pushed_time: 0.0,
            began,
            margin,
            started: false,
            longest_group: 0.0,
            joins_in_ring: 0,
            joins_at_end: 0,
            cuts: 0,
            last_end: None,
        })
    }

    /// The geometry stream's writer (to limit what it uses, in tests).
    pub fn writer(&mut self) -> &mut GeometryWriter<'a> {
        &mut self.writer
    }

    /// Slots the module has taken.
    fn taken(&self) -> u64 {
        self.pushed - self.channel.segments.len() as u64
    }

    /// Motion time queued in the ring.
    pub fn buffered(&mut self) -> f64 {
        let taken = self.taken();
        while self.in_ring.front().is_some_and(|&(k, _)| k < taken) {
            if let Some((_, t)) = self.in_ring.pop_front() {
                self.buffered -= t;
            }
        }
        while self.group_ends.front().is_some_and(|(k, _)| k + 1 < taken) {
            self.group_ends.pop_front();
        }
        while self.ring_groups.front().is_some_and(|g| g.end() < taken) {
            self.ring_groups.pop_front();
        }
        self.buffered.max(0.0)
    }

    /// Motion time queued in the ring up to slot `k` (its own included).
    fn queued_through(&mut self, k: u64) -> f64 {
        self.buffered();
        self.in_ring.iter().take_while(|&&(j, _)| j <= k).map(|&(_, t)| t).sum()
    }

    /// Where a re-plan at another feed override joins: the first group end in the ring with
    /// `lead` of motion queued before it (its slot number and end), or `None`: at the end of
    /// the slots sent.
    fn join_point(&mut self, lead: f64) -> Option<(u64, Box<GroupEnd>)> {
        let last = self.pushed.checked_sub(1)?;
        self.buffered();
        let (mut queued, mut slots) = (0.0, self.in_ring.iter().peekable());
        for (k, end) in &self.group_ends {
            if *k >= last {
                return None;
            }
            while let Some(&(_, t)) = slots.next_if(|(j, _)| j <= k) {
                queued += t;
            }
            if queued >= lead {
                return Some((*k, end.clone()));
            }
        }
        None
    }

    /// Where a re-plan at another feed override may cut in: the checked hold stops at least
    /// `lead` (s of motion) ahead of the module's last sample in the first group that has one
    /// (after the group whose first slot is `after`, if given), in records still to run or
    /// running (the group's first slot number and what the cut needs), or `None`.
    fn cut_point(&mut self, period: f64, lead: f64, after: Option<u64>) -> Option<(u64, Box<CutFrom>)> {
        let taken = self.taken();
        self.buffered();
        let target = self.channel.splice.samples() + (lead / period).ceil() as u64;
        let later = |g: &&RingGroup| after.is_none_or(|k| g.first > k);
        self.ring_groups.iter().filter(later).find_map(|g| {
            let candidates: Vec<(usize, u64)> = g
                .hold_samples
                .iter()
                .enumerate()
                .filter(|&(i, _)| g.first + i as u64 + 1 >= taken) // not run already
                .flat_map(|(i, samples)| samples.iter().filter(|&&n| n >= target).map(move |&n| (i, n)))
                .collect();
            let from = CutFrom {
                begin: *g.begin,
                records: g.records.clone(),
                candidates,
                feed_override: g.feed_override,
            };
            (!from.candidates.is_empty()).then(|| (g.first, Box::new(from)))
        })
    }

    /// Every slot has gone into the ring.
    pub fn done(&self) -> bool {
        self.current.is_none()
            && match &self.source {
                Source::Segments {
                    events, queue, total, ..
                } => events.is_none() && queue.is_empty() && total.is_some(),
                Source::Blocks {
                    events, queue, total, ..
                } => events.is_none() && queue.is_empty() && total.is_some(),
            }
    }

    /// Why the plan ended before the toolpath file did, once it has ended.
    pub fn plan_error(&self) -> Option<&str> {
        match &self.source {
            Source::Segments { error, .. } | Source::Blocks { error, .. } => error.as_deref(),
        }
    }

    /// Whether [`QUEUED_AHEAD`] seconds of motion ([`BLOCKS_QUEUED_AHEAD`] of path blocks) wait
    /// to be sent (the planner waits for them).
    fn queue_full(&self) -> bool {
        match &self.source {
            Source::Segments {
                queued,
                events: Some(_),
                ..
            } => *queued >= QUEUED_AHEAD,
            Source::Blocks {
                queued,
                events: Some(_),
                ..
            } => *queued >= BLOCKS_QUEUED_AHEAD,
            _ => false,
        }
    }

    /// Takes what the planner thread has handed out so far, up to [`QUEUED_AHEAD`].
    fn receive(&mut self) -> Result<(), String> {
        self.receive_replan();
        self.receive_blocks()?;
        let Source::Segments {
            events,
            queue,
            queued,
            total,
            error,
            replanner,
            ..
        } = &mut self.source
        else {
            return Ok(());
        };
        let replanning = replanner.as_ref().is_some_and(|r| r.pending.is_some());
        while let Some(rx) = events {
            if *queued >= QUEUED_AHEAD || (replanning && *queued >= REPLAN_PAUSE) {
                break;
            }
            match rx.try_recv() {
                Ok(PlanEvent::Group(g)) => {
                    self.planned += g.time;
                    self.groups_planned += 1;
                    if let (true, Some(r)) = (self.planned >= FIRST_LEAD_PLANNED, replanner.as_deref_mut()) {
                        // What a re-plan of this path will take to be ready, until one has been:
                        // what its first plan took to plan as much as a re-plan must.
                        r.ready_after.get_or_insert(self.began.elapsed().as_secs_f64());
                    }
                    *queued += g.time;
                    queue.push_back(g);
                }
                Ok(PlanEvent::Done { line, error: failed }) => {
                    say!("nurbs-planner: {line}");
                    *total = Some(self.planned);
                    *events = None;
                    *error = failed;
                }
                Ok(PlanEvent::Failed(e)) => return Err(e),
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => return Err(planner_thread_ended()),
            }
        }
        Ok(())
    }

    /// Takes the block groups a streamed plan has handed out so far, up to
    /// [`BLOCKS_QUEUED_AHEAD`].
    fn receive_blocks(&mut self) -> Result<(), String> {
        let Source::Blocks {
            events,
            queue,
            queued,
            total,
            error,
            ..
        } = &mut self.source
        else {
            return Ok(());
        };
        while let Some(rx) = events {
            if *queued >= BLOCKS_QUEUED_AHEAD {
                break;
            }
            match rx.try_recv() {
                Ok(BlockEvent::Group(g)) => {
                    self.planned += g.time;
                    self.groups_planned += 1;
                    *queued += g.time;
                    queue.push_back(g);
                }
                Ok(BlockEvent::Done { line, error: failed }) => {
                    say!("nurbs-planner: {line}");
                    *total = Some(self.planned);
                    *events = None;
                    *error = failed;
                }
                Ok(BlockEvent::Failed(e)) => return Err(e),
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => return Err(planner_thread_ended()),
            }
        }
        Ok(())
    }

    /// Asks for the motion at feed override `feed_override` (the operator's, clamped to what
    /// the machine allows): a streamed plan is planned again at it from a cut into a record at
    /// a checked hold stop the join lead ahead (learned by the [`Replanner`]; [`crate::cut`]),
    /// else from the first group end in the ring with that much motion before it (the module
    /// drops the old plan's slots after it there: [`nurbs_hal::channel::Splice`]), else from
    /// the end of the last group sent (or from its start while nothing has been sent), and the
    /// motion runs into the new plan there. 0 (a hold, which the module carries out) and small
    /// changes keep the plan. Plans sent whole keep their override.
    pub fn set_feed_override(&mut self, feed_override: f64) {
        {
            let Source::Segments { replanner: Some(r), .. } = &mut self.source else {
                return;
            };
            let close = |a: f64, b: f64| (a - b).abs() <= OVERRIDE_STEP * b;
            if feed_override.is_nan() || feed_override <= 0.0 || close(feed_override, r.asked) {
                return;
            }
            if r.pending.as_ref().is_some_and(|p| p.requested) {
                // The module is asked to join one already: this one follows once it has
                // answered.
                return;
            }
            r.asked = feed_override;
            if close(feed_override, r.feed_override) {
                // Back to the plan being sent: a re-plan on its way is not needed any more.
                r.pending = None;
                return;
            }
        }
        let (pushed, next_queued) = (self.pushed, self.next_queued);
        let last_end = self.last_end.clone();
        let (period, refused_in, lead) = match &self.source {
            Source::Segments { replanner: Some(r), .. } => (
                r.limits.period,
                r.cut_refused.filter(|&(o, _)| o == feed_override).map(|(_, g)| g),
                r.lead(),
            ),
            _ => return,
        };
        let cut = self.cut_point(period, lead, refused_in);
        let join = if cut.is_some() { None } else { self.join_point(lead) };
        let Source::Segments { replanner: Some(r), .. } = &mut self.source else {
            return;
        };
        let send_from = next_queued as usize;
        let cut_group = cut.is_some();
        let (start, from, place) = match (cut, &join, &last_end) {
            (Some((first, cut)), _, _) => {
                let (at_sample, seq) = (cut.candidates[0].1, cut.records[cut.candidates[0].0].seq);
                (
                    StreamStart::Cut { from: cut, send_from },
                    format!("motion sample {at_sample} (inside record {seq}) or a later one"),
                    Some((first, at_sample)),
                )
            }
            (None, Some((k, end)), _) => (
                StreamStart::After {
                    end: end.clone(),
                    send_from,
                },
                format!("the end of record {}", end.record.seq),
                Some((*k, AT_RECORD_END)),
            ),
            (None, None, Some(end)) => (
                StreamStart::After {
                    end: end.clone(),
                    send_from,
                },
                format!("the end of record {}", end.record.seq),
                None,
            ),
            // The path's last group has gone out: nothing left to plan.
            (None, None, None) if pushed > 0 => {
                say!("nurbs-planner: feed override {feed_override}: not taken, the path's last group has gone out and has no cut ahead of the module");
                return;
            }
            (None, None, None) => (StreamStart::Rest(r.from), "its start".to_string(), None),
        };
        say!("nurbs-planner: feed override {feed_override}: planning the rest of the motion again from {from}");
        r.pending = Some(Pending {
            events: spawn_plan(r.path.clone(), r.limits.clone(), start, feed_override),
            groups: VecDeque::new(),
            queued: 0.0,
            total: None,
            error: None,
            pushed,
            feed_override,
            began: Instant::now(),
            since: r.retry_since.take().unwrap_or_else(Instant::now),
            join: place,
            cut_group: cut_group.then_some(place.map_or(0, |(k, _)| k)),
            requested: false,
            first_group: None,
        });
    }

    /// Plans again at `feed_override` from a later place, a re-plan at it having failed to
    /// join (`since`: when the override was asked for, for the log).
    fn plan_again(&mut self, feed_override: f64, since: Instant) {
        if let Source::Segments { replanner: Some(r), .. } = &mut self.source {
            r.asked = r.feed_override;
            r.retry_since = Some(since);
        }
        self.set_feed_override(feed_override);
        if let Source::Segments { replanner: Some(r), .. } = &mut self.source {
            r.retry_since = None;
        }
    }

    /// Takes what a re-plan at another feed override has handed out; once it has a group, the
    /// motion runs into it: at a group end still queued once the module has accepted the join
    /// (asked while the module is [`SPLICE_LAST_CALL`] or more before it), or at the end of the
    /// slots sent if nothing was sent since it began. Otherwise it begins again from a later
    /// join. A re-plan that fails leaves the plan as it is.
    fn receive_replan(&mut self) {
        let pushed = self.pushed;
        let Source::Segments { replanner: Some(r), .. } = &mut self.source else {
            return;
        };
        let Some(p) = &mut r.pending else {
            return;
        };
        while p.queued < QUEUED_AHEAD && p.total.is_none() {
            match p.events.try_recv() {
                Ok(PlanEvent::Group(g)) => {
                    p.first_group.get_or_insert((Instant::now(), g.time));
                    p.queued += g.time;
                    p.groups.push_back(g);
                }
                Ok(PlanEvent::Done { line, error }) => {
                    say!("nurbs-planner: {line}");
                    p.total = Some(p.queued);
                    p.error = error;
                }
                Ok(PlanEvent::Failed(e)) if !p.requested && p.join.is_some_and(|(_, n)| n != AT_RECORD_END) => {
                    // No cut in that group: cut into a later one, or join at a group end.
                    say!(
                        "nurbs-planner: feed override {}: no cut into that group ({e}); trying a later one or a group end",
                        p.feed_override
                    );
                    let asked = p.feed_override;
                    // (The group it cuts into, or, where its groups came before it failed, the
                    // record it cut into: either way a later group is tried next.)
                    r.cut_refused = p.cut_group.or(p.join.map(|(k, _)| k)).map(|g| (asked, g));
                    let since = r.pending.take().map_or_else(Instant::now, |p| p.since);
                    self.plan_again(asked, since);
                    return;
                }
                Ok(PlanEvent::Failed(e)) if !p.requested => {
                    say!(
                        "nurbs-planner: feed override {} not taken, the motion goes on at {}: {e}",
                        p.feed_override,
                        r.feed_override
                    );
                    r.pending = None;
                    return;
                }
                Ok(PlanEvent::Failed(e)) => {
                    // Asked of the module already: the plan has failed after its first groups;
                    // it ends there, at rest at a checked stop, as an underrun.
                    say!(
                        "nurbs-planner: the re-plan at feed override {} failed: {e}",
                        p.feed_override
                    );
                    p.total = Some(p.queued);
                    p.error = Some(e);
                }
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => {
                    p.total = Some(p.queued);
                    break;
                }
            }
        }
        if p.groups.is_empty() {
            if p.total.is_some() && !p.requested {
                r.pending = None;
            }
            return;
        }
        if let (Some(first), Some(place)) = (p.cut_group, p.groups.front().and_then(|g| g.cut)) {
            // Where in the group the cut comes.
            p.join = Some((first + place.record as u64, place.at_sample));
            p.cut_group = None;
        }
        if !p.requested {
            // The motion runs into the new plan only once it could start on it: as much motion
            // ahead of the module, the old plan's up to the join and the new one's planned, at
            // the pace, as a motion from rest waits for ([`START_AHEAD`]). The pace counts from
            // the first group on (its wait is the time to join, not the pace it keeps) once a
            // second one has come.
            let rate = match p.first_group {
                Some((at, time)) if p.groups.len() >= 2 => (p.queued - time) / at.elapsed().as_secs_f64().max(1e-9),
                _ => p.queued / p.began.elapsed().as_secs_f64().max(1e-9),
            };
            let (queued, total, join) = (p.queued, p.total, p.join);
            let before_join = match join {
                None => self.buffered(),
                Some((k, AT_RECORD_END)) => self.queued_through(k),
                Some((_, n)) => n.saturating_sub(self.channel.splice.samples()) as f64 * r.limits.period,
            };
            let total = total.map_or(f64::INFINITY, |t| t + before_join);
            if !far_enough_ahead(queued + before_join, total, rate, START_AHEAD) {
                return;
            }
            let Source::Segments { replanner: Some(r), .. } = &mut self.source else {
                return;
            };
            let Some(p) = &mut r.pending else {
                return;
            };
            r.ready_after = Some(p.began.elapsed().as_secs_f64());
        }
        let Source::Segments { replanner: Some(r), .. } = &mut self.source else {
            return;
        };
        let Some(p) = &mut r.pending else {
            return;
        };
        if p.join.is_none() && p.pushed != pushed && p.pushed > 0 {
            // The old plan's next group went out meanwhile: the group end the re-plan starts
            // from is in the ring now, and the module may join there (dropping what went out
            // after it) if it is still far enough from it. Planning again after each group
            // that goes out would never catch up where a re-plan takes longer than a group.
            p.join = Some((p.pushed - 1, AT_RECORD_END));
        }
        let (join, requested, asked) = (p.join, p.requested, p.feed_override);
        match join {
            None if p.pushed != pushed => {
                // The old plan's first group went out meanwhile: plan again after it.
                let since = r.pending.take().map_or_else(Instant::now, |p| p.since);
                self.plan_again(asked, since);
                return;
            }
            None => {}
            Some((k, at_sample)) if !requested => {
                // The module must still be far enough from the join to answer in time.
                let join = Join {
                    after: self.ring_base.wrapping_add(k as u32),
                    drop_to: self.ring_base.wrapping_add(pushed as u32),
                    at_sample,
                };
                let period = r.limits.period;
                let ahead = if at_sample == AT_RECORD_END {
                    self.queued_through(k)
                } else {
                    at_sample.saturating_sub(self.channel.splice.samples()) as f64 * period
                };
                let Source::Segments { replanner: Some(r), .. } = &mut self.source else {
                    return;
                };
                if ahead < SPLICE_LAST_CALL || !self.channel.splice.request(join) {
                    if ahead < SPLICE_LAST_CALL {
                        r.lead = (2.0 * r.lead).min(JOIN_LEAD_MAX);
                    }
                    let since = r.pending.take().map_or_else(Instant::now, |p| p.since);
                    self.plan_again(asked, since);
                    return;
                }
                if let Some(p) = &mut r.pending {
                    p.requested = true;
                }
                return;
            }
            Some(_) => match self.channel.splice.state() {
                SPLICE_ACCEPTED | SPLICE_DONE => {}
                SPLICE_REQUESTED => return,
                _ => {
                    // Missed (too late, or the motion stopped): plan again from a later join,
                    // further ahead.
                    r.lead = (2.0 * r.lead).min(JOIN_LEAD_MAX);
                    let since = r.pending.take().map_or_else(Instant::now, |p| p.since);
                    self.plan_again(asked, since);
                    return;
                }
            },
        }
        let Source::Segments { replanner: Some(r), .. } = &mut self.source else {
            return;
        };
        let Some(p) = r.pending.take() else {
            return;
        };
        r.feed_override = p.feed_override;
        r.lead = JOIN_LEAD;
        let still_asked = r.asked;
        match p.join {
            Some((_, AT_RECORD_END)) => self.joins_in_ring += 1,
            Some(_) => self.cuts += 1,
            None => self.joins_at_end += 1,
        }
        if let Some((k, at_sample)) = p.join {
            // The module drops the old plan's slots after the join: they are not queued motion;
            // nor is the rest of the record a cut comes in.
            let cut = at_sample != AT_RECORD_END;
            let kept = |j: u64| j < k || (j == k && !cut);
            let mut dropped: f64 = self.in_ring.iter().filter(|&&(j, _)| !kept(j)).map(|&(_, t)| t).sum();
            let rest = p.groups.front().and_then(|g| g.cut).map_or(0.0, |c| c.dropped_time);
            if let Some(entry) = self.in_ring.iter_mut().find(|(j, _)| *j == k).filter(|_| cut) {
                // Still queued: the part before the cut stays.
                entry.1 -= rest;
                dropped -= entry.1;
            } else {
                dropped += rest;
            }
            self.in_ring.retain(|&(j, _)| j <= k);
            self.group_ends.retain(|&(j, _)| kept(j));
            self.ring_groups.retain(|g| g.end() <= k || (g.end() == k + 1 && !cut));
            self.buffered -= dropped;
            self.pushed_time -= dropped;
            self.channel.set_planned_time(self.pushed_time);
        }
        say!(
            "nurbs-planner: feed override {}: the motion runs into the new plan after slot {} ({}), re-planned in {:.1} ms ({:.1} ms after the override was asked for)",
            p.feed_override,
            p.join.map_or(pushed, |(k, _)| k + 1),
            match p.join {
                Some((_, AT_RECORD_END)) => "a group end the module accepted".to_string(),
                Some((_, n)) => format!("cutting into the record before it after motion sample {n}"),
                None => "the end of the slots sent".to_string(),
            },
            p.began.elapsed().as_secs_f64() * 1e3,
            p.since.elapsed().as_secs_f64() * 1e3
        );
        let Source::Segments {
            events,
            queue,
            queued,
            total,
            error,
            ..
        } = &mut self.source
        else {
            return;
        };
        *events = (p.total.is_none()).then_some(p.events);
        *queue = p.groups;
        *queued = p.queued;
        *total = p.total.map(|t| self.pushed_time + t);
        *error = p.error;
        self.planned = self.pushed_time + p.queued;
        // The old plan's group waiting to go out is not part of the motion any more.
        self.current = None;
        if (still_asked - p.feed_override).abs() > OVERRIDE_STEP * p.feed_override {
            // The knob moved on while the module answered.
            if let Source::Segments { replanner: Some(r), .. } = &mut self.source {
                r.asked = r.feed_override;
            }
            self.set_feed_override(still_asked);
        }
    }

    /// The next group from the source, if one is ready; the curves it is the first to need
    /// join the queue of curves to publish.
    fn next_group(&mut self) -> Result<Option<Group>, String> {
        let period = self.source.period();
        match &mut self.source {
            Source::Segments {
                queue,
                queued,
                replanner,
                ..
            } => {
                let Some(mut g) = queue.pop_front() else {
                    return Ok(None);
                };
                *queued -= g.time;
                let curve_needed = g.curve_needed();
                // A record's stored hold stops go into the arena with it in one piece: where
                // they would take more than an eighth of the arena the writer may use, the
                // record keeps its S-curve stops only.
                let most = self.writer.arena_capacity() / 8;
                for (slot, stops) in g.slots.iter_mut().zip(&mut g.hold_stops) {
                    if stops.values.len() > most {
                        *stops = stops.without_stored();
                        slot.hold_stops_len = stops.count as u32;
                    }
                }
                let feed_override = replanner.as_ref().map_or(1.0, |r| r.feed_override);
                self.queue_curves(g.first_curve, std::mem::take(&mut g.curves))?;
                let cut_data = g.begin.map(|begin| RingGroup {
                    first: 0, // set as it goes into the ring
                    records: g.slots.iter().map(|s| s.record).collect(),
                    begin,
                    hold_samples: g.hold_stops.iter().map(|stops| stops.samples().collect()).collect(),
                    feed_override,
                });
                Ok(Some(Group {
                    curve_needed,
                    times: g.slots.iter().map(|s| s.record.profile().total_time()).collect(),
                    slots: g.slots.iter().map(Slot::segment).collect(),
                    block_stop: None,
                    chain: (!g.chain.is_empty()).then_some(g.chain),
                    hold_stops: g.hold_stops,
                    hold_stops_written: 0,
                    end: g.end,
                    cut_data,
                }))
            }
            Source::Blocks { queue, queued, .. } => {
                let Some(g) = queue.pop_front() else {
                    return Ok(None);
                };
                *queued -= g.time;
                self.queue_curves(g.first_curve, g.curves)?;
                let last = g.blocks.len() - 1;
                Ok(Some(Group {
                    curve_needed: g.blocks[last].curve_needed,
                    times: g.blocks.iter().map(|b| b.len() as f64 * period).collect(),
                    slots: g.blocks.iter().map(Slot::block).collect(),
                    block_stop: Some(BlockStopData {
                        stored: g.stored,
                        points: Some(g.points),
                    }),
                    chain: None,
                    hold_stops: Vec::new(),
                    hold_stops_written: 0,
                    end: None,
                    cut_data: None,
                }))
            }
        }
    }

    /// Queues the curves a group is the first to need (`curves`, from curve `first` on) for
    /// the geometry stream: a re-plan may bring curves again that an earlier plan's groups
    /// brought (the same path), which are queued already.
    fn queue_curves(&mut self, first: u32, curves: Vec<Nurbs>) -> Result<(), String> {
        if !curves.is_empty() && first > self.next_queued {
            return Err(format!(
                "a group brings curves from {first}, but curve {} comes next",
                self.next_queued
            ));
        }
        let known = (self.next_queued.saturating_sub(first) as usize).min(curves.len());
        self.next_queued += (curves.len() - known) as u32;
        self.curves.extend(curves.into_iter().skip(known));
        Ok(())
    }

    /// Publishes the curves up to `needed`; false if there is no room for them yet.
    fn publish_curves(&mut self, needed: u32) -> Result<bool, String> {
        while self.writer.next_curve() <= needed {
            let c = self.writer.next_curve();
            let curve = self
                .curves
                .front()
                .ok_or_else(|| format!("a record needs curve {c}, beyond the path"))?;
            match self.writer.publish_curve(
                curve.degree(),
                curve.dim(),
                curve.knots(),
                curve.points(),
                curve.weights(),
            ) {
                Ok(()) => {
                    self.curves.pop_front();
                }
                Err(WriteError::Full) => return Ok(false),
                Err(WriteError::Refused(e)) => return Err(e),
            }
        }
        Ok(true)
    }

    /// Writes a segment group's stop chain into the arena and its offset into the last slot;
    /// false if there is no room yet.
    fn write_chain(&mut self, group: &mut Group) -> Result<bool, String> {
        let Some(values) = group.chain.take() else {
            return Ok(true);
        };
        // Needed until the module runs past the group's end.
        let last = group.slots.len() - 1;
        let written = self.put_for_slot(&values, group, last, |s, offset| s.chain_offset = offset)?;
        if !written {
            group.chain = Some(values);
        }
        Ok(written)
    }

    /// Writes the checked stops inside each record of a segment group into the arena and their
    /// offsets into the slots; false if there is no room yet (what is written stays written).
    fn write_hold_stops(&mut self, group: &mut Group) -> Result<bool, String> {
        while group.hold_stops_written < group.hold_stops.len() {
            let k = group.hold_stops_written;
            let values = std::mem::take(&mut group.hold_stops[k].values);
            // Needed while the module runs this record.
            if !values.is_empty() && !self.put_for_slot(&values, group, k, |s, offset| s.hold_stops_offset = offset)? {
                group.hold_stops[k].values = values;
                return Ok(false);
            }
            group.hold_stops_written += 1;
        }
        Ok(true)
    }

    /// Puts `values` into the arena, kept until the module has run slot `k` of `group`, and
    /// writes their offset into that slot with `set`; false if there is no room yet.
    fn put_for_slot(
        &mut self,
        values: &[f64],
        group: &mut Group,
        k: usize,
        set: impl FnOnce(&mut SegmentSlot, u32),
    ) -> Result<bool, String> {
        let offset = match self.writer.put(values, Release::Slot(self.pushed + k as u64)) {
            Ok(offset) => offset,
            Err(WriteError::Full) => return Ok(false),
            Err(WriteError::Refused(e)) => return Err(e),
        };
        if let Some(Record::Segment(mut s)) = group.slots[k].decode() {
            set(&mut s, offset);
            group.slots[k] = Slot::segment(&s);
        }
        Ok(true)
    }

    /// Path blocks: writes the arena data of the stop after the group's last block (its stored
    /// sequence, or its stop points) and fills in the offsets; false if there is no room yet
    /// (what is written stays written). Needed until the module runs past that block.
    fn write_block_data(&mut self, group: &mut Group) -> Result<bool, String> {
        let Some(data) = &mut group.block_stop else {
            return Ok(true);
        };
        let last = group.slots.len() - 1;
        let release = Release::Slot(self.pushed + last as u64);
        let Some(Record::Block(mut b)) = group.slots[last].decode() else {
            return Err("a block group's last slot holds no block".into());
        };
        for (values, stored) in [(&mut data.stored, true), (&mut data.points, false)] {
            let Some(list) = values.as_ref() else {
                continue;
            };
            let offset = if list.is_empty() {
                0
            } else {
                match self.writer.put(list, release) {
                    Ok(offset) => offset,
                    Err(WriteError::Full) => return Ok(false),
                    Err(WriteError::Refused(e)) => return Err(e),
                }
            };
            if stored {
                b.stop_offset = offset;
            } else {
                (b.points_offset, b.points_len) = (offset, (list.len() / 2) as u32);
            }
            *values = None;
            group.slots[last] = Slot::block(&b);
        }
        group.block_stop = None;
        Ok(true)
    }

    /// Sends what it can: curves ahead, groups while the margin and the ring allow. Returns
    /// whether it did anything.
    pub fn fill(&mut self) -> Result<bool, String> {
        let mut progressed = false;
        loop {
            self.receive()?;
            self.writer.reclaim(self.taken());
            self.release_path();
            if self.current.is_none() {
                self.current = self.next_group()?;
                if self.current.is_none() {
                    return Ok(progressed);
                }
                progressed = true;
            }
            let Some(mut group) = self.current.take() else {
                return Ok(progressed);
            };
            if group.slots.len() > SEGMENT_SLOTS {
                return Err(format!(
                    "a group of {} records without a stop between them does not fit the ring of {SEGMENT_SLOTS}",
                    group.slots.len()
                ));
            }
            let ready = self.publish_curves(group.curve_needed)?
                && self.write_block_data(&mut group)?
                && self.write_chain(&mut group)?
                && self.write_hold_stops(&mut group)?;
            if !ready && self.writer.held_values() == 0 && self.channel.segments.is_empty() {
                return Err("a group's curves and stops do not fit the channel's arena".into());
            }
            let room = SEGMENT_SLOTS - self.channel.segments.len() >= group.slots.len();
            if !(ready && room && self.may_push() && !self.replan_waits()) {
                self.current = Some(group);
                return Ok(progressed);
            }
            for (slot, time) in group.slots.iter().zip(&group.times) {
                self.channel
                    .segments
                    .producer()
                    .push(slot)
                    .map_err(|e| format!("channel: {e:?}"))?;
                self.in_ring.push_back((self.pushed, *time));
                self.buffered += time;
                self.pushed += 1;
                self.pushed_time += time;
            }
            if let Some(end) = &group.end {
                self.group_ends.push_back((self.pushed - 1, end.clone()));
            }
            if let Some(mut g) = group.cut_data.take() {
                g.first = self.pushed - group.slots.len() as u64;
                self.ring_groups.push_back(g);
            }
            self.longest_group = self.longest_group.max(group.times.iter().sum());
            self.last_end = group.end;
            self.channel.set_planned_time(self.pushed_time);
            progressed = true;
        }
    }

    /// Lets the path shared by the plans forget what no plan can start at any more: the
    /// elements before the module's, and before the first record of the oldest group a cut
    /// may replay ([`Streamer::cut_point`]), less one (a plan from rest at the end of an
    /// element, or a replay from the end of the record before, looks at it).
    fn release_path(&mut self) {
        self.buffered();
        let module = self.writer.module_curve();
        let replayed = self
            .ring_groups
            .front()
            .and_then(|g| g.records.first())
            .map(|r| r.curve);
        let floor = replayed.map_or(module, |c| c.min(module)).saturating_sub(1);
        match &self.source {
            Source::Segments { replanner: Some(r), .. } => r.path.release_before(floor as usize),
            Source::Blocks { path: Some(path), .. } => path.release_before(floor as usize),
            _ => {}
        }
    }

    /// Whether the old plan's next group waits for a re-plan at another feed override on its
    /// way (see [`REPLAN_LOW_WATER`]).
    fn replan_waits(&mut self) -> bool {
        let (to_ring_end, asked) = match &self.source {
            Source::Segments { replanner: Some(r), .. } => match &r.pending {
                Some(p) => (p.join.is_none(), p.requested),
                None => (false, false),
            },
            _ => (false, false),
        };
        // While the module is asked, nothing goes out: the new plan must land where it was
        // told to.
        asked || (to_ring_end && self.buffered() >= REPLAN_LOW_WATER)
    }

    /// Whether the start rule has held: records go into the ring.
    pub fn started(&self) -> bool {
        self.started
    }

    /// Whether the next group may go into the ring: within the margin once the motion has
    /// started; before, once the plan can stay ahead of the motion (a plan that fails by then
    /// moves nothing).
    fn may_push(&mut self) -> bool {
        if self.started {
            return self.buffered() < self.margin;
        }
        let total = match &self.source {
            Source::Segments { total, .. } => total.unwrap_or(f64::INFINITY),
            Source::Blocks { total, .. } => total.unwrap_or(f64::INFINITY),
        };
        let rate = self.planned / self.began.elapsed().as_secs_f64().max(1e-9);
        // With the queue full the planner waits for the motion: it cannot get further ahead.
        // The pace counts once it spans two groups: a plan's first group can come far sooner
        // than its pace (a smoothed dense program's first after 31 ms, its fourth 140 ms after
        // the third, for 75 ms of motion). A re-plan's first group comes at its pace.
        let paced = self.groups_planned >= 2 || self.planned >= total;
        let ahead = START_AHEAD.min(self.margin);
        self.started = (paced && far_enough_ahead(self.planned, total, rate, ahead)) || self.queue_full();
        self.started
    }
}
