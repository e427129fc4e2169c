#include "daemon/commission.hpp"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <stdexcept>

#include "daemon/gateway.hpp"
#include "daemon/log.hpp"
#include "daemon/offline.hpp"
#include "daemon/published_fields.hpp"
#include "daemon/resources.hpp"
#include "estimators/motor.hpp"
#include "protocol/codec.hpp"
#include "protocol/mapping.hpp"

namespace pumptherm::daemon {
namespace {

using protocol::MappingInput;

constexpr double kRadPerSPerRpm = 2.0 * 3.14159265358979323846 / 60.0;
/// Chi-square quantile, 1 degree of freedom, 95 %: the likelihood-ratio interval of the lag.
constexpr double kChiSquare1Dof95 = 3.841;
/// The mismatch test's NIS window (estimators::MismatchDetectorConfig::window_s).
constexpr std::int64_t kNisWindowUs = 60'000'000;
/// A measured period this far from the DBC's cycle time is worth a note.
constexpr double kPeriodTolerance = 0.25;
/// Speeds beyond this share of the motor's rated speed are implausible.
constexpr double kSpeedMargin = 1.25;
/// Findings of one kind listed one by one; the rest are counted.
constexpr std::size_t kListed = 5;

double Seconds(std::int64_t us) { return static_cast<double>(us) * 1e-6; }

/// Frames of one input message from one node on one interface.
struct Traffic {
  std::uint64_t frames = 0;
  std::int64_t first_us = -1, last_us = -1;
  std::int64_t max_gap_us = 0;
  std::uint64_t max_gap_line = 0;
};

/// One mapped input of one pump: its range over the recording and what was implausible.
struct InputSeen {
  double min = kNaN, max = kNaN;
  std::uint64_t values = 0, not_available = 0, implausible = 0;
  std::uint64_t first_implausible_line = 0;
  double first_implausible = kNaN;
};

/// Plausible range of an input: the DBC signal's declared range (when it has one), narrowed by
/// what the configuration and the motor say.
struct Range {
  double low = -std::numeric_limits<double>::infinity();
  double high = std::numeric_limits<double>::infinity();
  std::string why;
};

/// What the main run saw, frame by frame and step by step.
class Census {
 public:
  Census(const DaemonConfig& config, const protocol::Dbc& dbc,
         const protocol::SignalMapping& mapping)
      : config_(config), dbc_(dbc), mapping_(mapping), codec_(dbc) {
    for (std::size_t i = 0; i < protocol::kMappingInputCount; ++i) {
      const auto& ref = mapping.inputs[i];
      if (ref) input_messages_.insert(ref->message_index);
    }
    for (const auto& [key, ref] : mapping.outputs) output_messages_.insert(ref.message_index);
    for (const auto& [node, ref] : mapping.node_temperatures)
      output_messages_.insert(ref.message_index);
    for (std::size_t p = 0; p < config.pumps.size(); ++p) {
      motors_.push_back(LoadMotor(config.pumps[p]));
      inputs_.emplace_back(protocol::kMappingInputCount);
      auto& ranges = ranges_.emplace_back();
      for (std::size_t i = 0; i < protocol::kMappingInputCount; ++i)
        ranges.push_back(Plausible(p, static_cast<MappingInput>(i)));
    }
  }

  void OnFrame(const std::string& iface, const protocol::TimedFrame& tf, std::uint64_t line) {
    const protocol::CanFrame& f = tf.frame;
    if (f.error || f.remote) return;
    if (last_us_ >= 0 && tf.time_us - last_us_ > silence_us_) {
      ++silences_;
      if (silences_ <= kListed)
        silence_text_.push_back(fmt::format("{:.1f} s without any frame before line {}",
                                            Seconds(tf.time_us - last_us_), line));
    }
    last_us_ = tf.time_us;
    interfaces_.insert(iface);
    if (!f.extended && f.id == config_.gateway.heartbeat_id) ++heartbeats_[iface];
    for (int m : input_messages_) Match(iface, tf, line, m, true);
    for (int m : output_messages_) Match(iface, tf, line, m, false);
  }

  std::int64_t silence_us_ = 2'000'000;
  const std::set<std::string>& interfaces() const { return interfaces_; }
  /// (interface, message, node) -> traffic, for inputs; outputs of another gateway likewise.
  std::map<std::tuple<std::string, int, std::uint32_t>, Traffic> inputs_heard, outputs_heard;
  std::map<std::string, std::uint64_t> heartbeats_;
  std::vector<std::string> silence_text_;
  std::uint64_t silences_ = 0;
  /// Per configured pump, per mapping input.
  std::vector<std::vector<InputSeen>> inputs_;
  std::vector<estimators::MotorDescription> motors_;
  std::vector<std::vector<Range>> ranges_;  ///< per pump, per mapping input: Plausible()

  /// The plausible range of input `i` of pump `p`.
  Range Plausible(std::size_t p, MappingInput i) const {
    Range r;
    const auto& ref = mapping_.input(i);
    if (!ref) return r;
    const auto& s = dbc_.messages[static_cast<std::size_t>(ref->message_index)]
                        .signals[static_cast<std::size_t>(ref->signal_index)];
    if (s.maximum > s.minimum) {
      const double a = ref->scale * s.minimum + ref->offset,
                   b = ref->scale * s.maximum + ref->offset;
      r = {std::min(a, b), std::max(a, b), fmt::format("the DBC's range of {}", s.name)};
    }
    const auto& m = config_.pumps[p].alarms.monitor;
    const estimators::MotorDescription& motor = motors_[p];
    auto narrow = [&](double low, double high, std::string why) {
      r.low = std::max(r.low, low);
      r.high = std::min(r.high, high);
      r.why = std::move(why);
    };
    switch (i) {
      case MappingInput::kFrameSensorDegC:
      case MappingInput::kAmbientDegC:
        narrow(m.sensor_min_degC, m.sensor_max_degC,
               fmt::format("alarms.sensor_min_degC..sensor_max_degC ({}..{})", m.sensor_min_degC,
                           m.sensor_max_degC));
        break;
      case MappingInput::kSpeedMechRpm:
        if (motor.rated_speed_rpm > 0)
          narrow(-kSpeedMargin * motor.rated_speed_rpm, kSpeedMargin * motor.rated_speed_rpm,
                 fmt::format("{} x the rated {} r/min of {}", kSpeedMargin, motor.rated_speed_rpm,
                             motor.name));
        break;
      case MappingInput::kSpeedElecRadPerS:
        if (motor.rated_speed_rpm > 0) {
          const double w = kSpeedMargin * motor.rated_speed_rpm * motor.pole_pairs * kRadPerSPerRpm;
          narrow(-w, w,
                 fmt::format("{} x the rated {} r/min of {} ({} pole pairs)", kSpeedMargin,
                             motor.rated_speed_rpm, motor.name, motor.pole_pairs));
        }
        break;
      case MappingInput::kDcLinkV:
        narrow(0.0, r.high, "a DC link above 0 V");
        break;
      default:
        break;
    }
    return r;
  }

 private:
  estimators::MotorDescription LoadMotor(const PumpConfig& pc) const {
    if (!estimators::MotorPresetText(pc.motor).empty()) return estimators::MotorPreset(pc.motor);
    const std::string path = ResolveResource(ResourceKind::kMotor, pc.motor, config_.dbc.base_dir);
    return estimators::ParseMotorDescription(ReadTextFile(path), path);
  }

  void Match(const std::string& iface, const protocol::TimedFrame& tf, std::uint64_t line, int m,
             bool input) {
    const auto& msg = dbc_.messages[static_cast<std::size_t>(m)];
    const protocol::CanFrame& f = tf.frame;
    if (msg.extended != f.extended || f.id < msg.id || f.id - msg.id >= mapping_.node_id_limit)
      return;
    const std::uint32_t node = f.id - msg.id;
    Traffic& t = (input ? inputs_heard : outputs_heard)[{iface, m, node}];
    if (t.last_us >= 0 && tf.time_us - t.last_us > t.max_gap_us) {
      t.max_gap_us = tf.time_us - t.last_us;
      t.max_gap_line = line;
    }
    if (t.first_us < 0) t.first_us = tf.time_us;
    t.last_us = tf.time_us;
    ++t.frames;
    if (input) Values(iface, tf, line, m, node);
  }

  /// The mapped inputs of message `m` for the configured pump at (iface, node), if any.
  void Values(const std::string& iface, const protocol::TimedFrame& tf, std::uint64_t line, int m,
              std::uint32_t node) {
    for (std::size_t p = 0; p < config_.pumps.size(); ++p) {
      const PumpConfig& pc = config_.pumps[p];
      if (pc.node_id != node || pc.interface != iface) continue;
      const protocol::MessageCodec& codec = codec_.message(static_cast<std::size_t>(m));
      values_.resize(codec.signal_count());
      if (codec.Decode(std::span<const std::uint8_t>(tf.frame.data.data(), tf.frame.len),
                       values_) != protocol::CodecStatus::kOk)
        return;
      for (std::size_t i = 0; i < protocol::kMappingInputCount; ++i) {
        const auto& ref = mapping_.inputs[i];
        if (!ref || ref->message_index != m) continue;
        const auto input = static_cast<MappingInput>(i);
        if (input == MappingInput::kRollingCounter || input == MappingInput::kAlarmClear) continue;
        InputSeen& seen = inputs_[p][i];
        const double raw = values_[static_cast<std::size_t>(ref->signal_index)];
        if (std::isnan(raw)) {
          ++seen.not_available;
          continue;
        }
        const double v = ref->scale * raw + ref->offset;
        ++seen.values;
        seen.min = std::isnan(seen.min) ? v : std::min(seen.min, v);
        seen.max = std::isnan(seen.max) ? v : std::max(seen.max, v);
        const Range& range = ranges_[p][i];
        if (v < range.low || v > range.high) {
          if (seen.implausible++ == 0) {
            seen.first_implausible_line = line;
            seen.first_implausible = v;
          }
        }
      }
    }
  }

  const DaemonConfig& config_;
  const protocol::Dbc& dbc_;
  const protocol::SignalMapping& mapping_;
  protocol::DbcCodec codec_;
  std::set<int> input_messages_, output_messages_;
  std::set<std::string> interfaces_;
  std::vector<double> values_;
  std::int64_t last_us_ = -1;
};

/// What each pump's pipeline did in the main run.
struct PumpRun {
  std::vector<std::string> alarms;  ///< "warning at 839 s (estimated_over_temperature, winding)"
  std::uint64_t alarm_changes = 0;
  estimators::AlarmLevel level = estimators::AlarmLevel::kNone;
  estimators::AlarmReason reason = estimators::AlarmReason::kNone;
  int node = -1;
  /// The disturbance-state filter's heat balance after the first kSettle_s: the frame-path heat
  /// beyond the model's and the model's losses, summed over the steps, W.
  double frame_heat_sum_W = 0.0;
  double losses_sum_W = 0.0;
  int balance_steps = 0;
};

/// Runs the gateway over the log; `after` sees each Advance, `on_frame` each frame. Log lines
/// go to `log` (captured).
OfflineResult Run(
    const std::string& log_path, Gateway& gateway,
    std::function<void(const Gateway&, std::int64_t)> after,
    std::function<void(std::size_t, const protocol::TimedFrame&, std::uint64_t)> on_frame) {
  std::ifstream in = OpenLog(log_path);
  OfflineOptions o;
  o.after_advance = std::move(after);
  o.on_frame = std::move(on_frame);
  return RunOffline(in, log_path, gateway, o);
}

/// The heat balance is judged after the start's settling (its sds still wide).
constexpr std::int64_t kSettle_us = 300'000'000;
/// The frame-path heat against the model's losses that makes the model doubtful for this pump:
/// on the iron-loss grid (docs/virtual-sensor.md, "Cases no bench was tuned on") the pumps the
/// filter left uncovered at 0.1 needed 21 % or more; those it covered 17 % or less, but for one
/// at 27 %; the demo's healthy pumps 1-2 %.
constexpr double kDoubtfulHeatShare = 0.2;
/// The model_losses_sd_rel proposed then, which covered the iron grid (no trip late).
constexpr double kProposedLossesSd = 0.3;

/// Adds one step of pump `pump`'s heat balance to `run`: the frame-path heat its
/// disturbance-state filter needs beyond the model, and the model's losses at that step.
void AddHeatBalance(const Pump& pump, PumpRun& run) {
  const estimators::ThermalObserver& o = pump.estimator().observer();
  const double heat_W = o.FrameHeat_W();
  if (!std::isfinite(heat_W)) return;  // no such filter
  Eigen::VectorXd x(o.NodeCount());
  for (int i = 0; i < x.size(); ++i) x(i) = o.Node_degC(i);
  const double losses_W = pump.model().NodeLosses_W(pump.estimator().last_inputs(), x).sum();
  if (!std::isfinite(losses_W)) return;
  run.frame_heat_sum_W += heat_W;
  run.losses_sum_W += losses_W;
  ++run.balance_steps;
}

/// The sum of the mismatch test's NIS per pump, window by window, for one candidate lag.
struct NisRun {
  std::int64_t start_us = -1;                   // the first Advance
  std::vector<std::vector<double>> windows;     // per pump: the window sums, in order
  std::vector<std::vector<std::int64_t>> ends;  // per pump: when each window ended
  std::vector<std::int64_t> first_failure_us;   // per pump; INT64_MAX: never
};

bool Failed(estimators::MismatchState s) {
  return s == estimators::MismatchState::kPlantChange ||
         s == estimators::MismatchState::kSensorFaultSuspected ||
         s == estimators::MismatchState::kUnexplained;
}

NisRun RunLag(const DaemonConfig& base, const std::string& log_path, double lag_s) {
  DaemonConfig config = base;
  for (auto& pc : config.pumps) pc.frame_sensor_lag_s = lag_s;
  Gateway gateway(config);
  const std::size_t n = config.pumps.size();
  NisRun run;
  run.windows.resize(n);
  run.ends.resize(n);
  run.first_failure_us.assign(n, std::numeric_limits<std::int64_t>::max());
  std::vector<std::int64_t> next_us(n, -1);
  Run(
      log_path, gateway,
      [&](const Gateway& g, std::int64_t now) {
        if (run.start_us < 0) run.start_us = now;
        for (std::size_t p = 0; p < n; ++p) {
          const PumpSnapshot& s = g.pumps()[p]->snapshot();
          if (!s.initialised) continue;
          if (Failed(s.mismatch.state))
            run.first_failure_us[p] = std::min(run.first_failure_us[p], now);
          if (next_us[p] < 0) next_us[p] = now + kNisWindowUs;
          if (now >= next_us[p]) {
            run.windows[p].push_back(s.mismatch.window_nis);
            run.ends[p].push_back(now);
            next_us[p] = now + kNisWindowUs;
          }
        }
      },
      nullptr);
  return run;
}

using LagRuns = std::map<double, NisRun>;  // candidate lag (s) -> its run

/// Per candidate lag, pump `p`'s NIS summed over the windows that end before every candidate
/// has found the model wrong (a plant change no lag explains; a wrong lag alone may fail the
/// test earlier), and how many windows that is.
std::vector<std::pair<double, double>> NisSums(const LagRuns& runs, std::size_t p, int& windows,
                                               double& until_s) {
  std::int64_t cutoff = 0;
  for (const auto& [lag, r] : runs) cutoff = std::max(cutoff, r.first_failure_us[p]);
  until_s = cutoff == std::numeric_limits<std::int64_t>::max()
                ? kNaN
                : Seconds(cutoff - runs.begin()->second.start_us);
  std::vector<std::pair<double, double>> sums;
  windows = std::numeric_limits<int>::max();
  for (const auto& [lag, r] : runs) {
    double sum = 0.0;
    int n = 0;
    for (std::size_t w = 0; w < r.windows[p].size() && r.ends[p][w] <= cutoff; ++w) {
      sum += r.windows[p][w];
      ++n;
    }
    sums.emplace_back(lag, sum);
    windows = std::min(windows, n);
  }
  return sums;
}

/// Least-squares parabola y = a x^2 + b x + c through `points`; false when degenerate.
bool FitParabola(const std::vector<std::pair<double, double>>& points, double& a, double& b,
                 double& c) {
  // Normal equations of the 3 coefficients, x centred for conditioning.
  double mean = 0.0;
  for (const auto& [x, y] : points) mean += x;
  mean /= static_cast<double>(points.size());
  double s[5] = {0, 0, 0, 0, 0}, t[3] = {0, 0, 0};
  for (const auto& [x0, y] : points) {
    const double x = x0 - mean;
    double xp = 1.0;
    for (int k = 0; k < 5; ++k, xp *= x) {
      s[k] += xp;
      if (k < 3) t[k] += xp * y;
    }
  }
  // | s4 s3 s2 | |a|   |t2|
  // | s3 s2 s1 | |b| = |t1|
  // | s2 s1 s0 | |c|   |t0|
  const double m[3][3] = {{s[4], s[3], s[2]}, {s[3], s[2], s[1]}, {s[2], s[1], s[0]}};
  const double det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
                     m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
                     m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
  if (points.size() < 3 || std::abs(det) < 1e-12) return false;
  auto solve = [&](int col) {  // Cramer's rule
    double r[3][3];
    for (int i = 0; i < 3; ++i)
      for (int k = 0; k < 3; ++k) r[i][k] = k == col ? t[2 - i] : m[i][k];
    return (r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1]) -
            r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0]) +
            r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0])) /
           det;
  };
  const double ac = solve(0), bc = solve(1), cc = solve(2);
  // Back from centred x: a (x - m)^2 + b (x - m) + c.
  a = ac;
  b = bc - 2 * ac * mean;
  c = ac * mean * mean - bc * mean + cc;
  return true;
}

/// The lag of pump `p`: the minimum of a parabola fitted to the sums near the least one, and
/// the taus within kChiSquare1Dof95 of it.
LagFit FitLag(const LagRuns& runs, std::size_t p) {
  LagFit fit;
  const auto sums = NisSums(runs, p, fit.windows, fit.model_failed_s);
  const auto best = std::min_element(
      sums.begin(), sums.end(), [](const auto& x, const auto& y) { return x.second < y.second; });
  fit.lag_s = best->first;
  fit.low_s = sums.front().first;
  fit.high_s = sums.back().first;
  // The points near the minimum (within 8 times the interval's height), at least 3.
  std::vector<std::pair<double, double>> near;
  for (const auto& xy : sums) {
    if (xy.second <= best->second + 8 * kChiSquare1Dof95) near.push_back(xy);
  }
  const auto index = static_cast<std::size_t>(best - sums.begin());
  if (near.size() < 3 && index > 0 && index + 1 < sums.size())
    near = {sums[index - 1], sums[index], sums[index + 1]};
  double a = 0, b = 0, c = 0;
  if (!FitParabola(near, a, b, c) || a <= 0) return fit;
  fit.lag_s = -b / (2 * a);
  const double half = std::sqrt(kChiSquare1Dof95 / a);
  fit.low_s = fit.lag_s - half;
  fit.high_s = fit.lag_s + half;
  fit.identified =
      fit.windows >= 5 && fit.low_s > sums.front().first && fit.high_s < sums.back().first;
  return fit;
}

/// The coarse grid, then a finer one around each pump's first estimate.
std::vector<LagFit> FitLags(const DaemonConfig& config, const std::string& log_path,
                            const std::vector<double>& grid) {
  LagRuns runs;
  for (double lag : grid) runs.emplace(lag, RunLag(config, log_path, lag));
  std::set<double> fine;
  for (std::size_t p = 0; p < config.pumps.size(); ++p) {
    const LagFit first = FitLag(runs, p);
    for (double d = -6; d <= 6; d += 2) {
      const double lag = std::round(first.lag_s + d);
      if (lag >= grid.front() && lag <= grid.back() && !runs.contains(lag)) fine.insert(lag);
    }
  }
  for (double lag : fine) runs.emplace(lag, RunLag(config, log_path, lag));
  std::vector<LagFit> fits;
  for (std::size_t p = 0; p < config.pumps.size(); ++p) {
    LagFit fit = FitLag(runs, p);
    fit.pump = config.pumps[p].name;
    fit.configured_s = config.pumps[p].frame_sensor_lag_s;
    fits.push_back(fit);
  }
  return fits;
}

std::string Pct(double a, double b) { return fmt::format("{:+.0f} %", 100.0 * (a - b) / b); }

class Report {
 public:
  void Change(std::string text) {
    lines_.push_back("  change: " + text);
    changes.push_back(std::move(text));
  }
  void Note(std::string text) {
    lines_.push_back("  note: " + text);
    notes.push_back(std::move(text));
  }
  void Line(std::string text) { lines_.push_back(std::move(text)); }
  std::string Text() const { return fmt::format("{}\n", fmt::join(lines_, "\n")); }
  std::vector<std::string> changes, notes;

 private:
  std::vector<std::string> lines_;
};

/// Configured pumps against the nodes heard, and another gateway's frames.
void ReportNodes(const DaemonConfig& config, const protocol::Dbc& dbc, const Census& census,
                 Report& report) {
  std::map<std::pair<std::string, std::uint32_t>, std::uint64_t> heard;  // (iface, node) -> frames
  for (const auto& [key, t] : census.inputs_heard)
    heard[{std::get<0>(key), std::get<2>(key)}] += t.frames;
  std::set<std::pair<std::string, std::uint32_t>> configured;
  std::vector<std::string> silent;
  for (const auto& pc : config.pumps) {
    configured.insert({pc.interface, pc.node_id});
    if (!heard.contains({pc.interface, pc.node_id})) silent.push_back(pc.name);
  }
  std::vector<std::string> strangers;
  for (const auto& [key, frames] : heard) {
    if (!configured.contains(key))
      strangers.push_back(fmt::format("node {} on {} ({} frames)", key.second, key.first, frames));
  }
  for (const auto& pc : config.pumps) {
    if (heard.contains({pc.interface, pc.node_id})) continue;
    report.Change(fmt::format(
        "{} (node_id = {} on {}, line {}) is never heard: no input frame of node {} in the "
        "recording{}",
        pc.name, pc.node_id, pc.interface, pc.LineOf("node_id"), pc.node_id,
        strangers.empty() ? "; is the drive on this bus and powered?"
                          : fmt::format("; heard without a pump: {} (a wrong node_id?)",
                                        fmt::join(strangers, ", "))));
  }
  if (!strangers.empty() && silent.empty())
    report.Note(
        fmt::format("heard, but no pump configured for them: {} (add a [[pump]] to "
                    "estimate them; the daemon warns about them once a minute)",
                    fmt::join(strangers, ", ")));
  std::map<std::string, std::set<std::uint32_t>> others;
  std::set<std::string> other_messages;
  for (const auto& [key, t] : census.outputs_heard) {
    others[std::get<0>(key)].insert(std::get<2>(key));
    other_messages.insert(dbc.messages[static_cast<std::size_t>(std::get<1>(key))].name);
  }
  for (const auto& [iface, nodes] : others) {
    report.Change(fmt::format(
        "a gateway already sends on {}: {} of nodes {} are in the recording; two gateways on one "
        "bus send the same IDs (stop the other one, or give this one's pumps other IDs; if it "
        "was this one, record with it stopped)",
        iface, fmt::join(other_messages, ", "), fmt::join(nodes, ", ")));
  }
  for (const auto& [iface, n] : census.heartbeats_) {
    report.Note(
        fmt::format("{} frames with the heartbeat's ID 0x{:03X} on {}: another gateway "
                    "(gateway.heartbeat_id)?",
                    n, config.gateway.heartbeat_id, iface));
  }
}

/// Each input message's period and longest silence per pump, against the DBC and stale_after_s.
void ReportRates(const DaemonConfig& config, const protocol::Dbc& dbc, const Census& census,
                 Report& report) {
  report.Line(fmt::format("{:<12} {:<14} {:>8} {:>12} {:>10} {:>14}", "pump", "message", "frames",
                          "period_ms", "dbc_ms", "longest_gap_s"));
  for (const auto& pc : config.pumps) {
    const double stale_s = pc.alarms.monitor.stale_after_s;
    for (const auto& [key, t] : census.inputs_heard) {
      const auto& [iface, m, node] = key;
      if (iface != pc.interface || node != pc.node_id) continue;
      const auto& msg = dbc.messages[static_cast<std::size_t>(m)];
      const double period_ms =
          t.frames > 1 ? 1e3 * Seconds(t.last_us - t.first_us) / static_cast<double>(t.frames - 1)
                       : kNaN;
      const double dbc_ms = msg.cycle_time_ms && *msg.cycle_time_ms > 0 ? *msg.cycle_time_ms : kNaN;
      report.Line(fmt::format("{:<12} {:<14} {:>8} {:>12.2f} {:>10} {:>14.3f}", pc.name, msg.name,
                              t.frames, period_ms,
                              std::isnan(dbc_ms) ? std::string("-") : fmt::format("{}", dbc_ms),
                              Seconds(t.max_gap_us)));
      if (!std::isnan(period_ms) && !std::isnan(dbc_ms) &&
          std::abs(period_ms - dbc_ms) > kPeriodTolerance * dbc_ms)
        report.Note(fmt::format("{}: {} comes every {:.1f} ms, the DBC says {} ms ({})", pc.name,
                                msg.name, period_ms, dbc_ms, Pct(period_ms, dbc_ms)));
      if (!std::isnan(period_ms) && period_ms * 1e-3 >= stale_s)
        report.Change(fmt::format(
            "{}: {} comes every {:.2f} s, not more often than alarms.stale_after_s = {} s: the "
            "daemon would call the telemetry stale between frames; raise stale_after_s above "
            "{:.1f} s",
            pc.name, msg.name, period_ms * 1e-3, stale_s, 3 * period_ms * 1e-3));
      else if (Seconds(t.max_gap_us) > stale_s)
        report.Note(fmt::format(
            "{}: {} was silent {:.2f} s before line {} (alarms.stale_after_s = {} s): the daemon "
            "raises stale telemetry there",
            pc.name, msg.name, Seconds(t.max_gap_us), t.max_gap_line, stale_s));
    }
  }
}

const char* InputName(MappingInput i) { return protocol::MappingInputName(i).data(); }

void ReportValues(const DaemonConfig& config, const Census& census, Report& report) {
  for (std::size_t p = 0; p < config.pumps.size(); ++p) {
    for (std::size_t i = 0; i < protocol::kMappingInputCount; ++i) {
      const InputSeen& seen = census.inputs_[p][i];
      const auto input = static_cast<MappingInput>(i);
      if (seen.implausible > 0) {
        const Range r = census.Plausible(p, input);
        report.Change(fmt::format(
            "{}: {} outside its plausible range [{}, {}] ({}) in {} of {} frames, first {} at "
            "line {}; seen {} to {}: check the mapping's scale and offset, and the signal",
            config.pumps[p].name, InputName(input), r.low, r.high, r.why, seen.implausible,
            seen.values, seen.first_implausible, seen.first_implausible_line, seen.min, seen.max));
      }
      if (seen.not_available > 0 && seen.values == 0)
        report.Note(fmt::format("{}: {} was always \"not available\" ({} frames)",
                                config.pumps[p].name, InputName(input), seen.not_available));
    }
  }
}

/// The frame-path heat each pump's disturbance-state filter needed beyond the model, against the
/// model's losses. Much of it means a model that is off for that pump (its losses, or its
/// cooling): at the stated 10 % the filter puts a stator's extra heat on the frame path, and the
/// winding runs cold inside a narrow band.
void ReportHeatBalance(const DaemonConfig& config, const std::vector<PumpRun>& runs,
                       Report& report) {
  bool header = false;
  for (std::size_t p = 0; p < runs.size(); ++p) {
    const PumpRun& r = runs[p];
    if (r.balance_steps == 0 || !(r.losses_sum_W > 0.0)) continue;
    if (!header) {
      report.Line(fmt::format(
          "heat balance (the frame-path heat the filter needed beyond the model, on average "
          "after the first {:.0f} s, against the model's losses):",
          Seconds(kSettle_us)));
      header = true;
    }
    const PumpConfig& pc = config.pumps[p];
    const double heat_W = r.frame_heat_sum_W / r.balance_steps;
    const double losses_W = r.losses_sum_W / r.balance_steps;
    const double share = heat_W / losses_W;
    report.Line(fmt::format("  {:<12} {:+.1f} W, {:+.0f} % of {:.1f} W", pc.name, heat_W,
                            100.0 * share, losses_W));
    if (std::abs(share) <= kDoubtfulHeatShare || pc.model_losses_sd_rel >= kProposedLossesSd)
      continue;
    const bool given = pc.key_lines.contains("model_losses_sd_rel");
    const int line = pc.LineOf("model_losses_sd_rel");
    report.Change(fmt::format(
        "{}: set model_losses_sd_rel = {:g} ({}): the filter needed {:+.0f} % of the model's "
        "losses on the frame path, so the model's losses or cooling are off for this pump by more "
        "than the {:g} stated, and its interior may run cold inside a narrow band "
        "(docs/operator-guide.md, section 4); or check the cooling and improve the model from "
        "this recording (section 9)",
        pc.name, kProposedLossesSd,
        given ? fmt::format("line {}", line) : fmt::format("in the [[pump]] of line {}", line),
        100.0 * share, pc.model_losses_sd_rel));
  }
}

void ReportLags(const DaemonConfig& config, const std::vector<LagFit>& lags, Report& report) {
  if (lags.empty()) return;
  report.Line(
      "frame sensor lag (the mismatch test's NIS over the recording, minimised over "
      "the lag; 95 % likelihood-ratio interval):");
  for (std::size_t p = 0; p < lags.size(); ++p) {
    const LagFit& f = lags[p];
    const PumpConfig& pc = config.pumps[p];
    if (!f.identified) {
      report.Line(fmt::format(
          "  {:<12} not told by this recording ({} NIS windows{}; interval {:.0f}-{:.0f} s): "
          "keep frame_sensor_lag_s = {} s",
          pc.name, f.windows,
          std::isnan(f.model_failed_s)
              ? std::string()
              : fmt::format(", the model stopped fitting at {:.0f} s", f.model_failed_s),
          f.low_s, f.high_s, pc.frame_sensor_lag_s));
      continue;
    }
    report.Line(
        fmt::format("  {:<12} {:.1f} s (interval {:.1f}-{:.1f} s, {} NIS windows); "
                    "configured {} s",
                    pc.name, f.lag_s, f.low_s, f.high_s, f.windows, pc.frame_sensor_lag_s));
    if (pc.frame_sensor_lag_s < f.low_s || pc.frame_sensor_lag_s > f.high_s)
      report.Change(fmt::format(
          "{}: set frame_sensor_lag_s = {:.0f} (line {}): the recording fits {:.1f}-{:.1f} s, "
          "the configuration says {} s",
          pc.name, std::round(f.lag_s), pc.LineOf("frame_sensor_lag_s"), f.low_s, f.high_s,
          pc.frame_sensor_lag_s));
  }
}

}  // namespace

CommissionResult CommissionAgainst(const DaemonConfig& given, const std::string& log_path,
                                   const CommissionOptions& options) {
  std::vector<std::pair<LogLevel, std::string>> captured;
  LogCapture capture([&](LogLevel level, std::string_view line) {
    captured.emplace_back(level, std::string(line));
  });
  DaemonConfig config = given;
  // The frame layout, read again as the gateway reads it (the gateway keeps its own private).
  const protocol::Dbc dbc = protocol::ParseDbc(
      ReadTextFile(ResolveResource(ResourceKind::kDbc, config.dbc.file, config.dbc.base_dir)),
      config.dbc.file);
  const protocol::SignalMapping mapping = protocol::ParseMapping(
      ReadTextFile(ResolveResource(ResourceKind::kDbc, config.dbc.mapping, config.dbc.base_dir)),
      config.dbc.mapping, dbc, MappingOutputs());

  Report report;
  CommissionResult result;
  double stale_s = std::numeric_limits<double>::infinity();
  for (const auto& pc : config.pumps) stale_s = std::min(stale_s, pc.alarms.monitor.stale_after_s);
  auto main_run = [&](const DaemonConfig& c, Census& census, std::vector<PumpRun>& runs) {
    captured.clear();
    census.silence_us_ = static_cast<std::int64_t>(std::llround(stale_s * 1e6));
    std::int64_t start_us = -1;
    Gateway gateway(c);
    runs.assign(c.pumps.size(), PumpRun{});
    OfflineResult r = Run(
        log_path, gateway,
        [&](const Gateway& g, std::int64_t now) {
          for (std::size_t p = 0; p < runs.size(); ++p) {
            const PumpSnapshot& s = g.pumps()[p]->snapshot();
            PumpRun& pr = runs[p];
            if (s.initialised && now - start_us > kSettle_us) AddHeatBalance(*g.pumps()[p], pr);
            if (s.alarm_changes == pr.alarm_changes) continue;
            pr.alarm_changes = s.alarm_changes;
            if (s.alarm.level == pr.level && s.alarm.reason == pr.reason && s.alarm.node == pr.node)
              continue;
            pr.level = s.alarm.level;
            pr.reason = s.alarm.reason;
            pr.node = s.alarm.node;
            const auto& names = g.pumps()[p]->model().StateNames();
            const std::string node =
                s.alarm.node >= 0 && static_cast<std::size_t>(s.alarm.node) < names.size()
                    ? names[static_cast<std::size_t>(s.alarm.node)]
                    : std::string("-");
            if (pr.alarms.size() < kListed)
              pr.alarms.push_back(fmt::format(
                  "{} at {:.0f} s ({}, {})", estimators::AlarmLevelName(s.alarm.level),
                  Seconds(now - start_us), estimators::AlarmReasonName(s.alarm.reason), node));
          }
        },
        [&](std::size_t iface, const protocol::TimedFrame& tf, std::uint64_t line) {
          if (start_us < 0) start_us = tf.time_us;
          census.OnFrame(gateway.counter().interfaces()[iface].name, tf, line);
        });
    RequireFrames(r, log_path);
    return r;
  };

  auto census = std::make_unique<Census>(config, dbc, mapping);
  std::vector<PumpRun> runs;
  OfflineResult r = main_run(config, *census, runs);
  // A recording made on another interface name (a bench's vcan0): one bus on each side is read
  // as the same bus.
  std::set<std::string> configured_ifaces;
  for (const auto& i : config.interfaces) configured_ifaces.insert(i.name);
  bool any_configured_heard = false;
  for (const auto& i : census->interfaces()) any_configured_heard |= configured_ifaces.contains(i);
  if (!any_configured_heard && census->interfaces().size() == 1 && config.interfaces.size() == 1) {
    const std::string heard = *census->interfaces().begin();
    const std::string wanted = config.interfaces[0].name;
    report.Note(
        fmt::format("the recording is of {}, the configuration listens on {}: read as "
                    "the same bus",
                    heard, wanted));
    config.interfaces[0].name = heard;
    for (auto& pc : config.pumps) pc.interface = heard;
    census = std::make_unique<Census>(config, dbc, mapping);
    r = main_run(config, *census, runs);
  }
  result.frames = r.frames;
  const double duration_s = Seconds(r.last_us - r.first_us);

  report.Line(fmt::format("{} against {}", config.source, log_path));
  report.Line(fmt::format(
      "recording: {} frames in {:.1f} s on {}; stamps: {}; {} malformed and {} untimed lines "
      "skipped",
      r.frames, duration_s, fmt::join(census->interfaces(), ", "),
      protocol::CandumpTimeBaseName(r.time_base), r.bad_lines, r.untimed_lines));
  if (r.time_base != protocol::CandumpTimeBase::kAbsolute)
    report.Note(fmt::format("the stamps are {}: read as seconds since the recording's start",
                            protocol::CandumpTimeBaseName(r.time_base)));
  if (r.time_steps_back > 0)
    report.Note(
        fmt::format("the recording's clock goes back {} time{} (the daemon's warnings "
                    "below name the lines): concatenated logs, or the host's clock set",
                    r.time_steps_back, r.time_steps_back == 1 ? "" : "s"));
  if (r.bad_lines > 0)
    report.Note(
        fmt::format("{} lines are not candump lines (the warnings below name them)", r.bad_lines));

  ReportNodes(config, dbc, *census, report);
  ReportRates(config, dbc, *census, report);
  ReportValues(config, *census, report);

  if (census->silences_ > 0)
    report.Note(fmt::format(
        "the whole bus was silent longer than alarms.stale_after_s ({} s) {} "
        "time{}: {}{} (a silence, or the recording host's clock stepped "
        "forward: the daemon cannot tell them apart and raises stale "
        "telemetry)",
        stale_s, census->silences_, census->silences_ == 1 ? "" : "s",
        fmt::join(census->silence_text_, "; "), census->silences_ > kListed ? "; ..." : ""));

  // What the daemon would log and raise on this recording.
  // What the daemon would log, each distinct line once with how often (a warning repeated once
  // a minute is one thing to fix).
  std::vector<std::string> warnings;
  std::map<std::string, std::size_t> repeats;
  for (const auto& [level, line] : captured) {
    if (level > LogLevel::kWarning) continue;
    ++result.daemon_warnings;
    if (repeats[line]++ == 0) warnings.push_back(line);
  }
  for (auto& w : warnings) {
    if (repeats[w] > 1) w += fmt::format(" (x{})", repeats[w]);
  }
  for (std::size_t p = 0; p < runs.size(); ++p) {
    if (!runs[p].alarms.empty())
      report.Note(fmt::format("{} raised on this recording: {}", config.pumps[p].name,
                              fmt::join(runs[p].alarms, "; ")));
  }

  ReportHeatBalance(config, runs, report);

  // The lag means something only for pumps whose telemetry is in the recording.
  bool any_heard = false;
  for (const auto& [key, t] : census->inputs_heard) {
    for (const auto& pc : config.pumps)
      any_heard |= std::get<0>(key) == pc.interface && std::get<2>(key) == pc.node_id;
  }
  if (!options.lag_grid_s.empty() && any_heard) {
    result.lags = FitLags(config, log_path, options.lag_grid_s);
    ReportLags(config, result.lags, report);
  } else if (!options.lag_grid_s.empty()) {
    report.Line("frame sensor lag: not fitted, no configured pump is heard");
  }

  if (!warnings.empty()) {
    report.Line(fmt::format(
        "the daemon logs {} warning{} on this recording, {} different{}:", result.daemon_warnings,
        result.daemon_warnings == 1 ? "" : "s", warnings.size(),
        warnings.size() > kListed ? fmt::format(" (the first {})", kListed) : std::string()));
    for (std::size_t i = 0; i < warnings.size() && i < kListed; ++i)
      report.Line("  " + warnings[i]);
  }
  if (report.changes.empty()) {
    report.Line(fmt::format("OK: nothing to change ({} note{})", report.notes.size(),
                            report.notes.size() == 1 ? "" : "s"));
  } else {
    const std::vector<std::string> changes = report.changes;
    report.Line(
        fmt::format("{} change{} to make:", changes.size(), changes.size() == 1 ? "" : "s"));
    for (std::size_t i = 0; i < changes.size(); ++i)
      report.Line(fmt::format("  {}. {}", i + 1, changes[i]));
  }
  result.report = report.Text();
  result.changes = report.changes;
  result.notes = report.notes;
  return result;
}

}  // namespace pumptherm::daemon
