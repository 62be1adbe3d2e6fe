// Plausibility of edited motion: does the edited body turn and walk like its source?
//
// The measures of mocapedit.inspect.metrics (body facing, turning rate, walking direction
// deviation, the turn an edit gives a walk) and PlausibilityJob, which takes them all for
// #A agents at once: the figures of metrics.plausibility_of, one row per agent.
//
// Written in the style of ozz-animation's runtime jobs: inputs and outputs are non-owning
// views, Validate() lists every failure condition, Run() validates and then runs, per agent:
//
//   Facing (source, edited) -> TurningRates -> AtEditedSamples (the source at the frames
//   each edited sample plays) -> HeldSamplesOut -> EditTurn -> DirectionDeviation (as it
//   is, and turned by the edit) -> Extremes
//
// Everything is world space in stage units, seconds and radians (figures in degrees); the job
// knows nothing of USD. Matrices are row-major 4x4 in the row-vector convention (row k is the
// joint's local axis k, row 3 its position). The ground plane follows the up axis: ground
// coordinates are (x, -z) for Y up and (x, y) for Z up, so headings turn counter-clockwise
// about up. The arithmetic follows numpy's (numpy.unwrap, numpy.interp, pairwise sums), so
// the figures equal those of the numpy measures (mocapedit.solve.plausibility's peer) to
// rounding.
#pragma once

#include <cstddef>
#include <cstdint>

#include "mocapedit/errors.h"
#include "mocapedit/layering.h"  // Span

namespace mocapedit {

// The heading of a joint's facing at each of #T samples, radians counter-clockwise about up,
// in (-pi, pi]: the ground projection of the local axis whose up component has the smallest
// mean magnitude over the samples (the axis that stays the most horizontal: any joint
// convention works). `matrices`: #T * 16 values; `facing`: #T. up_axis: 1 (Y) or 2 (Z).
// Throws InvalidInput when the sizes disagree or up_axis is neither.
void JointFacing(Span<const double> matrices, int up_axis, Span<double> facing);

// Unsigned turning rate of a facing (#T radians, unwrapped first) between consecutive samples
// at #T increasing `seconds`, degrees per second: #T - 1 values (none for #T < 2).
// Throws InvalidInput when the sizes disagree or the seconds do not increase.
void TurningRates(Span<const double> facing, Span<const double> seconds, Span<double> rates);

// The angle (degrees, 0..180) between the edited and the source walking direction at each of
// #T samples: chords from each sample to the first one at least `chord` seconds later. NaN
// where the source chord is slower than `min_speed` (stage units per second) or has no end.
// `source` and `edited`: #T * 2 ground points paired by sample, `seconds`: #T increasing.
// `turn` (#T radians, or empty): the source chord is turned by turn[i] before comparing.
// Throws InvalidInput when the sizes disagree.
void DirectionDeviation(Span<const double> source, Span<const double> edited, Span<const double> seconds,
                        double min_speed, double chord, Span<const double> turn, Span<double> deviation);

// The turn (radians, counter-clockwise, unwrapped) an edit gives a walk at each of #T
// samples: from the source's chord to the edited chord over `span` seconds centred on the
// sample (cut at the ends); interpolated where the source does not walk over the span
// (slower than `min_speed`), held at the ends, 0 everywhere when it never walks. Arguments as
// DirectionDeviation's. Throws InvalidInput when the sizes disagree.
void EditTurn(Span<const double> source, Span<const double> edited, Span<const double> seconds, double min_speed,
              double span, Span<double> turn);

struct PlausibilityJob {
  // #A + 1 increasing offsets, each starting at 0: agent a owns source samples
  // source_offsets[a] .. source_offsets[a + 1] - 1, and edited samples likewise.
  Span<const std::int64_t> source_offsets;
  Span<const std::int64_t> edited_offsets;
  // #S source sample times (seconds) and facing joint world matrices (#S * 16).
  Span<const double> source_seconds;
  Span<const double> source_hip;
  // #E edited sample times (seconds) and matrices (#E * 16).
  Span<const double> edited_seconds;
  Span<const double> edited_hip;
  // #E fractional source frames each edited sample plays (a time map), or empty. With them
  // the source is compared at those frames and the time warp is seconds of the shot per
  // second of the source; without, edited samples pair with source samples by index
  // (resampled by fraction of the clip when the counts differ) and the time warp is the ratio
  // of their intervals.
  Span<const double> edited_frames;
  int up_axis = 1;  // 1: Y up, 2: Z up
  // The thresholds of mocapedit.inspect.metrics (which sets them: none has a default here).
  double walking_speed = 0;   // stage units per second below which the source does not walk
  double chord = 0;           // seconds of a walking direction's chord
  double edit_turn_span = 0;  // seconds over which an edit's turn is measured
  double spin_rate = 0;       // degrees per second above which a body spins

  // Outputs, #A each (see metrics.Plausibility). Agents with fewer than 2 source or edited
  // samples get rates 0, no spin, NaN deviations, edit turn 0, time warp (1, 1), frames -1.
  Span<double> max_facing_rate;          // degrees per second, edited
  Span<double> source_max_facing_rate;   // degrees per second, the source at the same samples
  Span<double> max_extra_facing_rate;    // largest edited rate less the source's
  Span<std::int64_t> worst_turn_frame;   // edited sample (interval start) where that is
  Span<std::int64_t> spin_frames;        // intervals over spin_rate where the source's is not
  Span<double> max_direction_deviation;  // degrees; NaN when the source never walks
  Span<std::int64_t> worst_direction_frame;  // edited sample where that is (-1: none)
  Span<double> max_turned_deviation;     // degrees, against the source turned by the edit (where
                                         // that turn is a guess, also against the source as is)
  Span<double> max_edit_turn;            // degrees, the largest turn the edit gives the walk
  Span<double> length_ratio;             // edited over source ground path of the facing joint
  Span<double> time_warp_min;            // smallest and largest time warp
  Span<double> time_warp_max;

  // Returns when the job can run. Otherwise throws InvalidInput naming the reason, when:
  //  - an offsets array is empty, does not start at 0 or decreases, or the two do not hold
  //    the same number of agents;
  //  - source_seconds (source_hip) does not hold #S (#S * 16) values, edited_seconds
  //    (edited_hip) #E (#E * 16), or edited_frames is neither empty nor #E values;
  //  - an output does not hold #A values;
  //  - up_axis is neither 1 nor 2; walking_speed, chord, edit_turn_span or spin_rate is not
  //    positive and finite;
  //  - an agent with 2 samples or more on both sides has edited sample times that do not
  //    increase, or (without edited_frames) source sample times that do not.
  void Validate() const;

  // Validates, then writes every output. Throws InvalidInput (outputs untouched) when
  // Validate() does.
  void Run() const;
};

}  // namespace mocapedit
