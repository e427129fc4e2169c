#pragma once
/// The value each node's alarm levels act on, and the sd published with the node (docs/daemon.md,
/// "Alarm rule"): the estimate, raised to the highest of the bounds that say where the
/// estimate is known to run low:
///  - while running blind (no temperature measured: the frame sensor failed and no other
///    reading stands in), the worst case of a cooling failure nothing could see (BlindBound),
///    started from the top of the estimate's band, x + k sd, when the measurements stopped (for
///    a stuck sensor, from that of the step that fused the reading's last change: it was fused
///    until the stuck test found it);
///  - during a telemetry silence, the worst case of the motor's largest current from the
///    estimate at its start, as it was silence_delay_s ago; after it, the load that may have
///    risen unseen (SilenceBound);
///  - with a filter that fuses a lagging reading as the node itself, the reading's rise over
///    its lag (LagBias);
///  - once the mismatch test has named heat inside, the nodes as if the frame-path heat found
///    since its onset were on the rotor (InsideHeatBound).
/// Where a bound lies above the estimate, the published sd is widened so that the band
/// x +- 2 sd reaches it (during a silence, the worst case now: BandTop_degC; the inside-heat
/// bound, a central value: past it by the filter's own 2 sd). Pure library: time enters as
/// arguments; no allocation per step outside a silence.

#include <Eigen/Dense>
#include <cstdint>
#include <limits>
#include <utility>
#include <vector>

#include "estimators/alarm_bounds.hpp"
#include "estimators/alarms.hpp"
#include "estimators/thermal_model.hpp"

namespace pumptherm::estimators {

/// The rule that set a node's alarm value (AlarmValues::ValueAndRule): the estimate itself, whose
/// levels act on x + k sd (the band rule), or the bound that raised it above the estimate.
enum class AlarmRule : std::uint8_t {
  kBand = 0,           ///< the estimate: x + k sd with the filter's own sd
  kLaggingSensor = 1,  ///< a lagging reading's rise over its lag (LagBias)
  kInsideHeat = 2,     ///< heat named inside, put on the rotor (InsideHeatBound)
  kBlind = 3,          ///< running blind: the worst case of an unseen cooling failure
  kSilence = 4,        ///< a telemetry silence: the worst case of the load it may hide
};
/// The rule's word in the CSV and the journal ("band", "lagging_sensor", "inside_heat", "blind",
/// "silence").
const char* AlarmRuleName(AlarmRule rule);

/// One step's facts for AlarmValues::Step.
struct AlarmValuesStep {
  std::int64_t end_us = 0;
  double period_s = 1.0;
  const ThermalInputs* inputs = nullptr;  ///< the step's inputs (held ones when not fresh)
  bool fresh_inputs = false;              ///< this step had telemetry
  /// No temperature measured this step (the frame sensor's fault is raised, or a blind stretch
  /// goes on) and the estimate is valid.
  bool blind = false;
  SensorFault fault = SensorFault::kNone;  ///< the frame sensor's, this step
  double reading_changed_s = 0.0;          ///< when its reading last changed (SensorHealth)
  /// The estimate after the step and the filter's own sd of each node (n); `valid` false: the
  /// filter left every physical range (the bounds are dropped).
  const Eigen::VectorXd* x_degC = nullptr;
  const Eigen::VectorXd* sd_K = nullptr;
  bool valid = true;
  /// The fused reading the estimate follows without modelling its lag (NaN: none).
  double lagging_degC = 0.0;
  double stale_after_s = 2.0;   ///< a silence is longer than this
  double trip_sd_factor = 2.0;  ///< the upper bound x + k sd that ends a silence's bound
  /// The observer's frame-path heat, W (NaN: an observer without it), and what the mismatch test
  /// says of heat inside with its fitted onset (InsideHeatBound).
  double frame_path_heat_W = std::numeric_limits<double>::quiet_NaN();
  InsideHeatVerdict inside_verdict = InsideHeatVerdict::kUnchanged;
  double inside_onset_s = std::numeric_limits<double>::quiet_NaN();
};

/// Where AlarmValues finds the nodes of the inside-heat bound.
struct InsideHeatNodes {
  int measured = -1;          ///< the frame sensor's node (-1: no bound)
  int rotor = -1;             ///< where heat inside is put (-1: no bound)
  double history_s = 1200.0;  ///< how far back the mismatch test's fitted onset may lie
};

class AlarmValues {
 public:
  /// For a network of `model`'s nodes; `lag_s` the lag of a reading the filter does not model
  /// (0: none); the ring of recent estimates reaches over the stuck test's flat time and the
  /// fault's hold (`config`); `silence` the load a telemetry silence may hide (its worst case
  /// acts config.silence_delay_s late); `inside` the nodes of the inside-heat bound (default:
  /// none). Throws std::invalid_argument for a period that is not positive or a negative delay,
  /// current or speed.
  AlarmValues(const ThermalModel& model, const AlarmConfig& config, double lag_s, double period_s,
              const SilenceWorstLoad& silence = {}, const InsideHeatNodes& inside = {});

  void Step(const AlarmValuesStep& step);
  /// The value node i's levels act on, for its estimate `estimate_degC`.
  double Value_degC(int i, double estimate_degC) const;
  /// Value_degC with the rule that set it: the bound that raised it above the estimate (the
  /// highest where several do; of equal ones the first in the order lagging sensor or inside
  /// heat, blind, silence), or kBand where none did.
  std::pair<double, AlarmRule> ValueAndRule(int i, double estimate_degC) const;
  /// The top of the band published for node i whose levels act on `value_degC` (Value_degC):
  /// that value, or during a silence the worst case now when higher (the levels see it
  /// silence_delay_s late).
  double BandTop_degC(int i, double value_degC) const;
  /// The sd published for node i whose filter sd is `filter_sd_K` and whose alarm value lies
  /// `above_K` above its estimate (NaN or <= 0: none): at least above_K / 2, and at least
  /// filter_sd_K plus half the inside-heat bound's shift.
  double PublishedSd_K(int i, double filter_sd_K, double above_K) const;
  /// The inside-heat bound (latched, its heat).
  const InsideHeatBound& inside_heat() const { return inside_; }
  /// Forgets the inside-heat bound (a restore: the mismatch test that named the heat starts
  /// afresh, and the frame-path heat it was measured on may restart from its prior).
  void ForgetInsideHeat() { inside_.Reset(); }
  /// A blind bound is running (the previous step was blind).
  bool Blind() const { return blind_.bound_degC().size() > 0; }
  /// A silence from `start_s` (a restart: the time down), from the saved estimate and inputs;
  /// its worst case while still silent from `now_degC` at `now_s` (SilenceBound::Begin).
  void BeginSilence(const Eigen::VectorXd& x_degC, const ThermalInputs& in, double start_s,
                    const Eigen::VectorXd& now_degC, double now_s) {
    silence_.Begin(x_degC, in, start_s, now_degC, now_s);
  }

 private:
  void StepBlind(const AlarmValuesStep& s);
  void Remember(const AlarmValuesStep& s);
  /// x + k sd of the step (k: trip_sd_factor), into `out_degC` (sized: no allocation).
  static void UpperBand(const AlarmValuesStep& s, Eigen::Ref<Eigen::VectorXd> out_degC);

  const ThermalModel& model_;
  BlindBound blind_;
  LagBias lag_bias_;
  SilenceBound silence_;
  InsideHeatBound inside_;
  // The blind bound's starting points of the last steps, each the top of its step's band
  // x + k sd (columns, a ring; time -1: none).
  Eigen::MatrixXd recent_degC_;
  std::vector<std::int64_t> recent_us_;
  std::size_t recent_next_ = 0;
  Eigen::VectorXd blind_start_degC_;
};

}  // namespace pumptherm::estimators
