//! Timing several ray casters on the same segments in turns ([`time_in_turns`]): this
//! machine's speed drifts by tens of percent within minutes, so casters timed one after the
//! other compare badly; taking turns every few milliseconds makes the drift weigh on each alike
//! and keeps their ratios (`raybench`, the study's ray-casting units). A caster is anything
//! that answers the three query kinds over a slice of segments ([`TurnCaster`]): our
//! [`RayCaster`], or Embree for scale ([`EmbreeCaster`](super::embree::EmbreeCaster)).

use super::{RayCaster, Segment};
use rayon::prelude::*;
use std::time::Instant;

/// A caster [`time_in_turns`] can time: its queries over a slice of segments, each returning
/// a count (so that the work cannot be left out).
pub trait TurnCaster: Sync {
    /// Batch occlusion (several rays in flight per thread where the caster can): the number
    /// of occluded segments.
    fn count_occluded(&self, segs: &[Segment]) -> u64;
    /// One occlusion query at a time, over the thread pool: the number of occluded segments.
    fn count_occluded_single(&self, segs: &[Segment]) -> u64;
    /// Closest-hit queries, over the thread pool: the number of segments that hit.
    fn count_hits(&self, segs: &[Segment]) -> u64;
}

impl TurnCaster for RayCaster<'_> {
    fn count_occluded(&self, segs: &[Segment]) -> u64 {
        RayCaster::count_occluded(self, segs)
    }

    fn count_occluded_single(&self, segs: &[Segment]) -> u64 {
        segs.par_iter()
            .with_min_len(256)
            .filter(|s| self.occluded(s.origin, s.dir, s.tmin, s.tmax))
            .count() as u64
    }

    fn count_hits(&self, segs: &[Segment]) -> u64 {
        self.closest_batch(segs).iter().flatten().count() as u64
    }
}

/// Segments each caster casts in its turn.
pub const TURN: usize = 16_384;

/// Segments of a turn cast untimed first, so that the caster's data are back in the caches the
/// others used since its last turn.
pub const WARM: usize = 1_024;

/// What [`time_in_turns`] measured, per caster: seconds summed over the passes, and the counts
/// of the last pass.
#[derive(Clone, Debug, Default)]
pub struct TurnTimes {
    /// Batch occlusion ([`TurnCaster::count_occluded`]).
    pub batch_s: Vec<f64>,
    /// One query at a time ([`TurnCaster::count_occluded_single`]).
    pub single_s: Vec<f64>,
    /// Closest hits ([`TurnCaster::count_hits`]), when asked for.
    pub closest_s: Vec<f64>,
    /// Segments the batch found occluded.
    pub batch_occluded: Vec<u64>,
    /// Segments the single queries found occluded (equal to `batch_occluded` unless a
    /// traversal is wrong).
    pub single_occluded: Vec<u64>,
}

/// Cast `segs` `passes` times through every caster: batch occlusion, single queries and (with
/// `closest`) closest hits. Within a pass the casters take turns every [`TURN`] segments, in an
/// order rotated at each turn, each turn after [`WARM`] of its segments cast untimed. `tick` is
/// called after each round of turns.
pub fn time_in_turns(
    casters: &[&dyn TurnCaster],
    segs: &[Segment],
    passes: usize,
    closest: bool,
    tick: impl Fn(),
) -> TurnTimes {
    let n = casters.len();
    let mut t = TurnTimes {
        batch_s: vec![0.0; n],
        single_s: vec![0.0; n],
        closest_s: vec![0.0; n],
        batch_occluded: vec![0; n],
        single_occluded: vec![0; n],
    };
    for pass in 0..passes {
        t.batch_occluded.fill(0);
        t.single_occluded.fill(0);
        for (k, c) in segs.chunks(TURN).enumerate() {
            for j in 0..n {
                let i = (j + k + pass) % n;
                let rc = casters[i];
                std::hint::black_box(rc.count_occluded(&c[..WARM.min(c.len())]));
                let t0 = Instant::now();
                t.batch_occluded[i] += rc.count_occluded(c);
                t.batch_s[i] += t0.elapsed().as_secs_f64();
                let t0 = Instant::now();
                t.single_occluded[i] += rc.count_occluded_single(c);
                t.single_s[i] += t0.elapsed().as_secs_f64();
                if closest {
                    let t0 = Instant::now();
                    std::hint::black_box(rc.count_hits(c));
                    t.closest_s[i] += t0.elapsed().as_secs_f64();
                }
            }
            tick();
        }
    }
    t
}
