//! Sequences of references: segments played one after the other, each for its duration.
//!
//! Each [`Segment`] holds a [`Reference`] evaluated at the local time `t - start` (so a segment's
//! `t0` is relative to its own start) and either
//! * a position reference for the closed loop ([`Target::Position`], load angle [rad]), or
//! * an open-loop driver input ([`Target::Voltage`]): the generator's value is read as volts
//!   (`step:2` is a 2 V step), its speed and acceleration are ignored.
//!
//! With [`SegmentMode::Absolute`] the segment's value is used as is; with
//! [`SegmentMode::Chained`] the final value of the previous segment of the same target is added,
//! so that e.g. ramp, hold, ramp back continue from where the previous one ended.
//!
//! Times within [`TIME_EPS_S`] (1 ns) of a segment boundary count as at it, so `k * T_s`
//! sample times switch on the intended sample. Before the first segment the first segment's value at its start holds; after the last one a
//! position holds its final value (speed 0) and a voltage is 0 V.
//!
//! The segment arithmetic works on slices of [`PlacedSegment`], so the allocation-free
//! [`Sequence`] and a heap-backed list (the experiment files of servo-cli) share it.

use super::reference::{RefParseError, RefSample, Reference, TIME_EPS_S};

/// What a segment drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum Target {
    /// Closed loop: the reference is the load angle [rad].
    #[default]
    Position,
    /// Open loop: the reference's value is the driver input u [V].
    Voltage,
}

/// How a segment's value relates to the previous segment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum SegmentMode {
    /// The reference's value as is.
    #[default]
    Absolute,
    /// The reference's value plus the final value of the previous segment of the same target.
    Chained,
}

/// One piece of a sequence.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Segment {
    /// The generator, evaluated at the local time since the segment's start.
    pub reference: Reference,
    /// How long the segment lasts [s] (> 0, finite).
    pub duration_s: f64,
    /// Absolute or chained.
    pub mode: SegmentMode,
    /// Position (closed loop) or voltage (open loop).
    pub target: Target,
}

/// A segment with its start time and the base value added to it (from chaining).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct PlacedSegment {
    pub segment: Segment,
    /// Start time [s] from the beginning of the sequence.
    pub start_s: f64,
    /// Value added to the reference [rad or V]: 0 when absolute, else the chained value.
    pub base: f64,
}

/// What to apply at one instant of a sequence.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum Setpoint {
    /// Closed loop on this load-angle reference.
    Position(RefSample),
    /// Open loop: apply this driver input [V].
    Voltage { u_v: f64 },
}

/// Why a segment could not be added.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum SequenceError {
    /// The fixed-capacity sequence is full.
    #[error("too many segments: at most {0}")]
    Full(usize),
    /// Duration not finite or not > 0.
    #[error("segment {index}: `duration_s` must be > 0 s and finite, got {value}")]
    BadDuration { index: usize, value: f64 },
    /// The segment's reference does not validate.
    #[error("segment {index}: {source}")]
    Reference { index: usize, source: RefParseError },
}

impl Segment {
    /// A position segment, absolute.
    pub fn position(reference: Reference, duration_s: f64) -> Segment {
        Segment {
            reference,
            duration_s,
            mode: SegmentMode::Absolute,
            target: Target::Position,
        }
    }
    /// An open-loop voltage segment, absolute (the reference's value is read in V).
    pub fn voltage(reference: Reference, duration_s: f64) -> Segment {
        Segment {
            reference,
            duration_s,
            mode: SegmentMode::Absolute,
            target: Target::Voltage,
        }
    }
    /// The same segment, chained to the previous one.
    pub fn chained(self) -> Segment {
        Segment {
            mode: SegmentMode::Chained,
            ..self
        }
    }
}

impl PlacedSegment {
    /// Places `segment` after the already placed `previous` ones (index = previous.len()).
    pub fn after(
        previous: &[PlacedSegment],
        segment: Segment,
    ) -> Result<PlacedSegment, SequenceError> {
        let index = previous.len();
        if !(segment.duration_s.is_finite() && segment.duration_s > 0.0) {
            return Err(SequenceError::BadDuration {
                index,
                value: segment.duration_s,
            });
        }
        segment
            .reference
            .validate()
            .map_err(|source| SequenceError::Reference { index, source })?;
        let start_s = previous.last().map_or(0.0, |p| p.end_s());
        let base = match segment.mode {
            SegmentMode::Absolute => 0.0,
            SegmentMode::Chained => previous
                .iter()
                .rev()
                .find(|p| p.segment.target == segment.target)
                .map_or(0.0, |p| p.final_value()),
        };
        Ok(PlacedSegment {
            segment,
            start_s,
            base,
        })
    }

    /// End time [s].
    pub fn end_s(&self) -> f64 {
        self.start_s + self.segment.duration_s
    }

    /// Value at the end of the segment [rad or V].
    pub fn final_value(&self) -> f64 {
        self.base + self.segment.reference.at(self.segment.duration_s).pos_rad
    }

    fn local(&self, t_s: f64) -> RefSample {
        let mut r = self.segment.reference.at((t_s - self.start_s).max(0.0));
        r.pos_rad += self.base;
        r
    }

    fn setpoint(&self, t_s: f64) -> Setpoint {
        let r = self.local(t_s);
        match self.segment.target {
            Target::Position => Setpoint::Position(r),
            Target::Voltage => Setpoint::Voltage { u_v: r.pos_rad },
        }
    }
}

/// Total duration [s] of placed segments.
pub fn duration_s(slots: &[PlacedSegment]) -> f64 {
    slots.last().map_or(0.0, |p| p.end_s())
}

/// The setpoint at time `t_s` [s] (binary search over the segments). An empty sequence gives a
/// zero position reference.
pub fn setpoint_at(slots: &[PlacedSegment], t_s: f64) -> Setpoint {
    let Some(last) = slots.last() else {
        return Setpoint::Position(RefSample::default());
    };
    if t_s >= last.end_s() - TIME_EPS_S {
        return match last.segment.target {
            Target::Position => Setpoint::Position(RefSample::at_rest(last.final_value())),
            Target::Voltage => Setpoint::Voltage { u_v: 0.0 },
        };
    }
    let first = &slots[0];
    if t_s < first.start_s - TIME_EPS_S {
        return match first.setpoint(first.start_s) {
            Setpoint::Position(r) => Setpoint::Position(RefSample::at_rest(r.pos_rad)),
            v => v,
        };
    }
    // Index of the last segment starting at or before t.
    let i = slots
        .partition_point(|p| p.start_s <= t_s + TIME_EPS_S)
        .saturating_sub(1);
    slots[i].setpoint(t_s)
}

/// An allocation-free sequence of at most `N` segments.
#[derive(Debug, Clone)]
pub struct Sequence<const N: usize> {
    placed: [PlacedSegment; N],
    len: usize,
}

impl<const N: usize> Default for Sequence<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Sequence<N> {
    /// An empty sequence.
    pub fn new() -> Self {
        let filler = PlacedSegment {
            segment: Segment::position(Reference::step(0.0, 0.0), 1.0),
            start_s: 0.0,
            base: 0.0,
        };
        Sequence {
            placed: [filler; N],
            len: 0,
        }
    }

    /// Appends a segment after the last one.
    pub fn push(&mut self, segment: Segment) -> Result<(), SequenceError> {
        if self.len == N {
            return Err(SequenceError::Full(N));
        }
        let p = PlacedSegment::after(self.segments(), segment)?;
        self.placed[self.len] = p;
        self.len += 1;
        Ok(())
    }

    /// The placed segments.
    pub fn segments(&self) -> &[PlacedSegment] {
        &self.placed[..self.len]
    }

    /// Total duration [s].
    pub fn duration_s(&self) -> f64 {
        duration_s(self.segments())
    }

    /// The setpoint at time `t_s` [s].
    pub fn at(&self, t_s: f64) -> Setpoint {
        setpoint_at(self.segments(), t_s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::reference::Shape;

    fn pos(s: Setpoint) -> RefSample {
        match s {
            Setpoint::Position(r) => r,
            Setpoint::Voltage { .. } => panic!("expected a position"),
        }
    }

    #[test]
    fn padova_steps_alternate_every_two_seconds() {
        let mut seq: Sequence<16> = Sequence::new();
        for deg in [10.0, 30.0, 50.0] {
            let a: f64 = deg * crate::math::PI / 180.0;
            seq.push(Segment::position(Reference::step(a, 0.0), 2.0))
                .unwrap();
            seq.push(Segment::position(Reference::step(0.0, 0.0), 2.0))
                .unwrap();
        }
        assert_eq!(seq.duration_s(), 12.0);
        let deg = |t: f64| pos(seq.at(t)).pos_rad * 180.0 / crate::math::PI;
        assert!((deg(0.0) - 10.0).abs() < 1e-12);
        assert!((deg(1.999) - 10.0).abs() < 1e-12);
        assert!(deg(2.0).abs() < 1e-12);
        assert!((deg(4.5) - 30.0).abs() < 1e-12);
        assert!((deg(9.0) - 50.0).abs() < 1e-12);
        assert!(deg(11.0).abs() < 1e-12);
        assert!(deg(100.0).abs() < 1e-12);
        assert!((deg(-1.0) - 10.0).abs() < 1e-12);
        // Floating-point sample times just below a boundary switch on the intended sample:
        // 8.001 - 0.001 = 7.999999999999999 is the start of the 50 deg segment.
        assert!((deg(8.001 - 0.001) - 50.0).abs() < 1e-12);
        assert!(deg(1.999_999_999_9).abs() < 1e-12);
    }

    #[test]
    fn chained_ramps_continue_and_hold() {
        let mut seq: Sequence<4> = Sequence::new();
        let up = Reference::new(Shape::Ramp { speed_rad_s: 2.0 });
        seq.push(Segment::position(up, 1.0)).unwrap(); // 0 -> 2 rad
        seq.push(Segment::position(Reference::step(0.0, 0.0), 0.5).chained())
            .unwrap(); // hold 2
        let down = Reference::new(Shape::Ramp { speed_rad_s: -4.0 });
        seq.push(Segment::position(down, 0.5).chained()).unwrap(); // 2 -> 0
        let s = pos(seq.at(0.5));
        assert!((s.pos_rad - 1.0).abs() < 1e-12 && s.vel_rad_s == 2.0);
        let s = pos(seq.at(1.2));
        assert!((s.pos_rad - 2.0).abs() < 1e-12 && s.vel_rad_s == 0.0);
        let s = pos(seq.at(1.75));
        assert!((s.pos_rad - 1.0).abs() < 1e-12 && s.vel_rad_s == -4.0);
        let s = pos(seq.at(5.0));
        assert!(s.pos_rad.abs() < 1e-12 && s.vel_rad_s == 0.0);
        // Capacity is enforced.
        seq.push(Segment::position(up, 1.0)).unwrap();
        assert_eq!(
            seq.push(Segment::position(up, 1.0)),
            Err(SequenceError::Full(4))
        );
    }

    #[test]
    fn voltage_segments_and_errors() {
        let mut seq: Sequence<4> = Sequence::new();
        seq.push(Segment::voltage(Reference::step(2.0, 0.0), 1.0))
            .unwrap();
        seq.push(Segment::position(Reference::step(1.0, 0.0), 1.0))
            .unwrap();
        assert_eq!(seq.at(0.5), Setpoint::Voltage { u_v: 2.0 });
        assert!(matches!(seq.at(1.5), Setpoint::Position(r) if r.pos_rad == 1.0));
        let e = seq
            .push(Segment::position(Reference::step(1.0, 0.0), 0.0))
            .unwrap_err();
        assert_eq!(
            e,
            SequenceError::BadDuration {
                index: 2,
                value: 0.0
            }
        );
        let bad = Reference::new(Shape::Sine {
            amplitude_rad: 1.0,
            freq_hz: -1.0,
            phase_rad: 0.0,
        });
        let e = seq.push(Segment::position(bad, 1.0)).unwrap_err();
        assert!(matches!(e, SequenceError::Reference { index: 2, .. }));
        let mut v: Sequence<2> = Sequence::new();
        v.push(Segment::voltage(Reference::step(2.0, 0.0), 1.0))
            .unwrap();
        assert_eq!(v.at(3.0), Setpoint::Voltage { u_v: 0.0 });
    }
}
