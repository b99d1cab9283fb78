//! The geometry stream as the module follows it: the published header, the curves checked so
//! far (a slice of values per period, in path order) and their views.

use super::*;

/// The geometry stream the motion runs on: its header, how far its curves are checked, and the
/// channel's descriptors and arena. A curve's view is made when it is needed, in O(1): it was
/// checked once, in path order, a slice of values per period (`RtGeometry::follow`).
pub struct RtGeometry {
    /// Generation of the channel's stream (0: none).
    pub(super) generation: u32,
    pub(super) header: GeometryHeader,
    pub(super) tip: usize,
    pub(super) stream: Option<&'static GeometryStream>,
    /// Curves from `header.first_curve` up to (not including) this one are checked ...
    pub(super) checked: u32,
    /// ... and this one up to this value.
    pub(super) cursor: ValueCursor,
    /// The last curve asked for.
    cache: Cell<Option<(usize, CurveView<'static>)>>,
}

/// What [`RtGeometry::follow`] saw.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Followed {
    /// The same stream (perhaps more curves checked).
    Same,
    /// A new stream began: a new motion.
    New,
}

impl RtGeometry {
    pub(super) fn empty() -> RtGeometry {
        RtGeometry {
            generation: 0,
            header: GeometryHeader::default(),
            tip: 2,
            stream: None,
            checked: 0,
            cursor: 0,
            cache: Cell::new(None),
        }
    }

    /// The arena (empty before a stream).
    pub(super) fn values(&self) -> &'static [f64] {
        self.stream.map_or(&[], |s| s.values())
    }

    /// Curve `index`, if the stream has it checked. O(1).
    pub(super) fn valid(&self, index: usize) -> Option<CurveView<'static>> {
        if let Some((i, c)) = self.cache.get() {
            if i == index {
                return Some(c);
            }
        }
        let stream = self.stream?;
        let index32 = u32::try_from(index).ok()?;
        if index32 < self.header.first_curve || index32 >= self.checked {
            return None;
        }
        let desc = stream.descriptor(index32)?;
        let c = trusted_curve(&desc, stream.values(), self.tip).ok()?;
        self.cache.set(Some((index, c)));
        Some(c)
    }

    pub(super) fn is_valid(&self) -> bool {
        self.generation != 0
    }

    /// Takes a new stream of `stream` (only while no motion runs: `Err(GeometryChanged)`
    /// otherwise), and checks up to [`VALIDATION_VALUES_PER_PERIOD`] more values of the
    /// published curves, in path order. Bounded work, allocation-free, panic-free.
    pub(super) fn follow(
        &mut self,
        stream: &'static GeometryStream,
        in_motion: bool,
        period_ns: i64,
    ) -> Result<Followed, FaultCode> {
        let generation = stream.generation();
        let mut followed = Followed::Same;
        if generation != self.generation && generation != 0 && generation & 1 == 0 {
            if in_motion {
                return Err(FaultCode::GeometryChanged);
            }
            let header = stream.header();
            if !stream.unchanged(generation) {
                return Ok(Followed::Same); // begun again meanwhile: next period
            }
            validate_header(&header).map_err(|_| FaultCode::Geometry)?;
            if !period_matches(header.period_ns, period_ns) {
                return Err(FaultCode::Period);
            }
            *self = RtGeometry {
                generation,
                header,
                tip: header.tip_axes as usize,
                stream: Some(stream),
                checked: header.first_curve,
                cursor: 0,
                cache: Cell::new(None),
            };
            followed = Followed::New;
        }
        if self.generation == 0 {
            return Ok(followed);
        }
        let (published, values) = (stream.published(), stream.values());
        let mut budget = VALIDATION_VALUES_PER_PERIOD;
        while budget > 0 && self.checked < published {
            let desc = stream.descriptor(self.checked).ok_or(FaultCode::Geometry)?;
            let (used, next) =
                check_curve(&desc, values, self.tip, self.cursor, budget).map_err(|_| FaultCode::Geometry)?;
            budget = budget.saturating_sub(used);
            match next {
                Some(cursor) => self.cursor = cursor,
                None => (self.checked, self.cursor) = (self.checked.saturating_add(1), 0),
            }
        }
        Ok(followed)
    }
}

impl CurveSet for RtGeometry {
    fn curve(&self, index: usize) -> Option<CurveView<'_>> {
        self.valid(index)
    }
    fn tip_axes(&self) -> usize {
        self.tip
    }
    fn generation(&self) -> u64 {
        u64::from(self.generation)
    }
}
