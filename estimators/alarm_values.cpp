#include "estimators/alarm_values.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

namespace pumptherm::estimators {
namespace {

/// Standard deviations on either side of a published estimate that its band spans (the "+-2 sd"
/// the docs and the judges state coverage for).
constexpr double kPublishedBandSds = 2.0;

}  // namespace

AlarmValues::AlarmValues(const ThermalModel& model, const AlarmConfig& config, double lag_s,
                         double period_s, const SilenceWorstLoad& silence,
                         const InsideHeatNodes& inside)
    : model_(model),
      lag_bias_(lag_s, period_s),
      silence_(silence, config.silence_delay_s),
      inside_(model, inside.measured, inside.rotor, inside.history_s, std::max(period_s, 10.0)) {
  const int n = model.StateCount();
  // The ring reaches back over the stuck test's flat time and the fault's hold, plus a margin.
  const double reach_s = config.flat_after_s + config.hold_s + 2.0 * period_s;
  const auto ring = static_cast<std::size_t>(std::ceil(reach_s / period_s)) + 1;
  recent_degC_ = Eigen::MatrixXd::Zero(n, static_cast<Eigen::Index>(ring));
  recent_us_.assign(ring, -1);
  blind_start_degC_ = Eigen::VectorXd::Zero(n);
}

void AlarmValues::Step(const AlarmValuesStep& s) {
  StepBlind(s);
  Remember(s);
  // A filter that models the sensor's lag gets no bias (lagging_degC NaN).
  lag_bias_.Step(s.lagging_degC);
  if (!s.valid) {
    silence_.Reset();
    inside_.Reset();
    return;
  }
  inside_.Step(static_cast<double>(s.end_us) * 1e-6, s.frame_path_heat_W, s.inside_verdict,
               s.inside_onset_s);
  silence_.Step(model_, *s.inputs, s.fresh_inputs, *s.x_degC, *s.sd_K,
                static_cast<double>(s.end_us) * 1e-6, s.period_s, s.stale_after_s,
                s.trip_sd_factor);
}

void AlarmValues::StepBlind(const AlarmValuesStep& s) {
  if (!s.blind) {
    blind_.Reset();
    return;
  }
  if (!Blind() && s.fault == SensorFault::kStuck) {
    // A stuck reading is fused until the stuck test finds it (flat_after_s): the estimate has
    // followed a frozen value since, low if the pump warmed. The worst case starts from the
    // band's top at the step that fused the reading's last change, run to now in one step.
    const auto changed_us = static_cast<std::int64_t>(std::llround(s.reading_changed_s * 1e6));
    std::int64_t from_us = -1;
    Eigen::Index from = -1;
    for (std::size_t k = 0; k < recent_us_.size(); ++k) {
      const std::int64_t t = recent_us_[k];
      if (t >= changed_us && t < s.end_us && (from_us < 0 || t < from_us)) {
        from_us = t;
        from = static_cast<Eigen::Index>(k);
      }
    }
    if (from >= 0) {
      blind_start_degC_ = recent_degC_.col(from);  // sized at construction: no allocation
      blind_.Step(model_, *s.inputs, static_cast<double>(s.end_us - from_us) * 1e-6,
                  blind_start_degC_);
      return;
    }
  }
  // The worst case starts from the top of the band the estimate had (x + k sd), not from the
  // estimate: what the pump may already have been when it went blind. Only the first blind step
  // reads it (BlindBound::Step).
  if (!Blind()) UpperBand(s, blind_start_degC_);
  blind_.Step(model_, *s.inputs, s.period_s, blind_start_degC_);
}

void AlarmValues::UpperBand(const AlarmValuesStep& s, Eigen::Ref<Eigen::VectorXd> out_degC) {
  out_degC = *s.x_degC;
  if (s.sd_K != nullptr && s.sd_K->size() == out_degC.size()) {
    out_degC += s.trip_sd_factor * s.sd_K->cwiseMax(0.0);
  }
}

void AlarmValues::Remember(const AlarmValuesStep& s) {
  if (!s.valid) {
    std::fill(recent_us_.begin(), recent_us_.end(), -1);
    return;
  }
  UpperBand(s, recent_degC_.col(static_cast<Eigen::Index>(recent_next_)));
  recent_us_[recent_next_] = s.end_us;
  recent_next_ = (recent_next_ + 1) % recent_us_.size();
}

const char* AlarmRuleName(AlarmRule rule) {
  switch (rule) {
    case AlarmRule::kBand:
      return "band";
    case AlarmRule::kLaggingSensor:
      return "lagging_sensor";
    case AlarmRule::kInsideHeat:
      return "inside_heat";
    case AlarmRule::kBlind:
      return "blind";
    case AlarmRule::kSilence:
      return "silence";
  }
  return "band";
}

double AlarmValues::Value_degC(int i, double estimate_degC) const {
  return ValueAndRule(i, estimate_degC).first;
}

std::pair<double, AlarmRule> AlarmValues::ValueAndRule(int i, double estimate_degC) const {
  // The highest of: the estimate raised by the lagging reading's bias, the nodes as if the heat
  // found on the frame path were inside, the worst case while running blind, the worst case of a
  // telemetry silence (as it was silence_delay_s ago), and the bound after one.
  std::pair<double, AlarmRule> v{estimate_degC, AlarmRule::kBand};
  const auto raise = [&v](double candidate_degC, AlarmRule rule) {
    if (candidate_degC > v.first) v = {candidate_degC, rule};
  };
  const double lag_K = lag_bias_.bias_K();
  const double inside_K = inside_.shift_K(i);
  if (lag_K > 0.0 || inside_K > 0.0) {
    raise(estimate_degC + std::max(lag_K, inside_K),
          inside_K > lag_K ? AlarmRule::kInsideHeat : AlarmRule::kLaggingSensor);
  }
  const std::pair<const Eigen::VectorXd*, AlarmRule> bounds[] = {
      {&blind_.bound_degC(), AlarmRule::kBlind},
      {&silence_.bound_degC(), AlarmRule::kSilence},
      {&silence_.delayed_worst_degC(), AlarmRule::kSilence}};
  for (const auto& [b, rule] : bounds) {
    if (b->size() > i && !std::isnan((*b)(i))) raise((*b)(i), rule);
  }
  return v;
}

double AlarmValues::BandTop_degC(int i, double value_degC) const {
  const Eigen::VectorXd& w = silence_.worst_degC();
  return w.size() > i && !std::isnan(w(i)) ? std::max(value_degC, w(i)) : value_degC;
}

double AlarmValues::PublishedSd_K(int i, double filter_sd_K, double above_K) const {
  // Where the levels act on a bound above the estimate (running blind, after a silence, behind
  // a lagging sensor), the truth may lie up to that bound: the published band reaches it, so
  // that a node that cannot be seen says so through its sd. The estimate itself stays the
  // model's most likely value, and the alarms keep the filter's own sd (the bound already
  // stands for the worst case). The inside-heat bound is the other hypothesis's central value,
  // with the filter's own uncertainty about it: the band reaches that far past it.
  const double inside_K = inside_.shift_K(i);
  double sd = filter_sd_K;
  if (inside_K > 0.0) sd = filter_sd_K + inside_K / kPublishedBandSds;
  if (!(above_K > 0.0)) return sd;
  return std::max(sd, above_K / kPublishedBandSds);
}

}  // namespace pumptherm::estimators
