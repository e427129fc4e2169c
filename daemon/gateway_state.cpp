// The gateway's saved state (docs/daemon.md, "State across restarts"): every pump's estimate,
// identifier state and latched trips in TOML, written and restored, with the older version still
// read.
#include <fmt/format.h>
#include <toml++/toml.h>

#include <algorithm>
#include <cmath>
#include <ctime>
#include <limits>

#include "daemon/gateway.hpp"
#include "daemon/log.hpp"

namespace pumptherm::daemon {

namespace {

// Sizes of the identifier's saved arrays: per hypothesis the state x = [Rs, psi_f, ...] and its
// covariance P (row-major); the excitation moments of [iq, w_r, 1] (version 2) or of [iq, w_r]
// (files written before the offset column, still read).
constexpr int kIdentStates = 4;
constexpr int kIdentCovariance = kIdentStates * kIdentStates;
constexpr int kMomentsSide = 3;
constexpr int kMoments = kMomentsSide * kMomentsSide;
constexpr int kOldMomentsSide = 2;
constexpr int kOldMoments = kOldMomentsSide * kOldMomentsSide;

/// `m` row by row (a vector: its elements) as a TOML array.
toml::array Flattened(const Eigen::Ref<const Eigen::MatrixXd>& m) {
  toml::array a;
  for (Eigen::Index i = 0; i < m.rows(); ++i) {
    for (Eigen::Index j = 0; j < m.cols(); ++j) a.push_back(m(i, j));
  }
  return a;
}

/// The filter's and the identifier's state of one pump into its saved table.
void InsertEstimate(const PumpSavedState& s, std::int64_t wall_offset_us, toml::table& t) {
  t.insert("time_us", s.time_us + wall_offset_us);
  t.insert("x_degC", Flattened(s.x_degC));
  t.insert("s_K2", Flattened(s.s_K2));
  t.insert("inputs", toml::table{{"speed_rpm", s.inputs.speed_rpm},
                                 {"id_A", s.inputs.id_A},
                                 {"iq_A", s.inputs.iq_A},
                                 {"ambient_degC", s.inputs.ambient_degC},
                                 {"coolant_degC", s.inputs.coolant_degC}});
  // The disturbance-state filter's frame sensor offset, its sd and the sum of its steps (K):
  // a sensor that stepped stays known as such; absent in older files and without that filter.
  if (std::isfinite(s.sensor_offset_K) && std::isfinite(s.sensor_offset_sd_K) &&
      std::isfinite(s.stepped_offset_K)) {
    t.insert("frame_sensor_offset_K",
             toml::array{s.sensor_offset_K, s.sensor_offset_sd_K, s.stepped_offset_K});
  }
  // The disturbance-state filter's whole state and covariance (row-major): what it found about
  // the plant outlives a restart; absent in older files and without that filter.
  if (s.observer_x.size() > 0) {
    t.insert("disturbance_x", Flattened(s.observer_x));
    t.insert("disturbance_s", Flattened(s.observer_s));
    // Whether that calibration was learnt from a cold start (absent in older files: not).
    t.insert("disturbance_cold_started", s.cold_started);
    // The magnet law the check gave up (absent: none).
    if (!std::isnan(s.magnet_law_given_up_per_K))
      t.insert("disturbance_magnet_law_given_up_per_K", s.magnet_law_given_up_per_K);
    // The frame sensor's lag taken from the diagnosis and the lag configured then, s (absent:
    // none taken).
    if (!std::isnan(s.taken_sensor_lag_s)) {
      t.insert("disturbance_frame_sensor_lag_s",
               toml::array{s.taken_sensor_lag_s, s.taken_over_configured_lag_s});
    }
    // How far the losses were stated to be off the model's (absent in older files: 0.1).
    if (!std::isnan(s.losses_sd_rel)) t.insert("disturbance_model_losses_sd_rel", s.losses_sd_rel);
  }
  // Per magnet hypothesis (steady, then drifting): x (4), P (16, row-major), probability,
  // consecutive rejections.
  toml::array rx, rp, rprob, rrej, rm;
  for (const auto& h : s.resistance.hypotheses) {
    for (int i = 0; i < kIdentStates; ++i) rx.push_back(h.x(i));
    for (int i = 0; i < kIdentCovariance; ++i)
      rp.push_back(h.p(i / kIdentStates, i % kIdentStates));
    rprob.push_back(h.probability);
    rrej.push_back(h.consecutive_rejections);
  }
  // Excitation moments of [iq, w_r, 1] (9, row-major); files with 4 ([iq, w_r]) still load.
  for (int i = 0; i < kMoments; ++i)
    rm.push_back(s.resistance.moments(i / kMomentsSide, i % kMomentsSide));
  t.insert("resistance_x", rx);
  t.insert("resistance_p", rp);
  t.insert("resistance_probability", rprob);
  t.insert("resistance_rejections", rrej);
  t.insert("resistance_moments", rm);
  t.insert("resistance_blocks", static_cast<std::int64_t>(s.resistance.blocks));
  // What uq has drifted since the last load change (the status rests on it: held above
  // drift_hold_K); absent in older files, then measured afresh from the first block.
  if (s.resistance.anchor_valid) {
    toml::array anchor;
    for (int i = 0; i < kIdentStates; ++i) anchor.push_back(s.resistance.anchor(i));
    t.insert("resistance_anchor", anchor);
    t.insert("resistance_drift_V", s.resistance.drift_V);
    t.insert("resistance_drift_ohm", s.resistance.drift_ohm);
  }
}

/// The latched trips of one saved pump (two parallel arrays; both absent: none). False for a
/// damaged pair.
bool ReadLatchedTrips(const toml::table& t, std::vector<PumpSavedState::LatchedTrip>& out) {
  out.clear();
  const toml::array* nodes = t["latched_trip_nodes"].as_array();
  const toml::array* values = t["latched_trip_values_degC"].as_array();
  if (!nodes && !values) return true;
  if (!nodes || !values || nodes->size() != values->size()) return false;
  for (std::size_t k = 0; k < nodes->size(); ++k) {
    const auto node = (*nodes)[k].value<std::string>();
    const auto value = (*values)[k].value<double>();
    if (!node || !value || !std::isfinite(*value)) return false;
    out.push_back({*node, *value});
  }
  return true;
}

/// The array `key` of `t` as `n` finite numbers in `out`; false when absent, of another size or
/// not all finite numbers.
bool Numbers(const toml::table& t, const char* key, std::size_t n, std::vector<double>& out) {
  const toml::array* a = t[key].as_array();
  if (!a || a->size() != n) return false;
  out.clear();
  for (const auto& e : *a) {
    auto v = e.value<double>();
    if (!v || !std::isfinite(*v)) return false;
    out.push_back(*v);
  }
  return true;
}

/// The identifier's saved arrays of one pump (read by Numbers: x, P, moments, probabilities,
/// rejections) and its other keys.
struct IdentifierArrays {
  const std::vector<double>& rx;
  const std::vector<double>& rp;
  const std::vector<double>& rm;
  const std::vector<double>& rprob;
  const std::vector<double>& rrej;
};

/// The resistance identifier's saved state from its arrays (version 1: one filter, version 2:
/// one per magnet hypothesis) into `out`. False for damage the identifier's Restore would not
/// see (a rejection count that is not a small integer).
bool ReadIdentifierState(const toml::table& t, std::int64_t version, const IdentifierArrays& a,
                         const estimators::ResistanceIdentifierConfig& config,
                         estimators::ResistanceIdentifierState& out) {
  const std::size_t hypotheses_count = version == 1 ? 1 : estimators::kMagnetHypotheses;
  const auto& rx = a.rx;
  const auto& rp = a.rp;
  const auto& rm = a.rm;
  const auto& rprob = a.rprob;
  const auto& rrej = a.rrej;
  bool ok = true;
  Eigen::Matrix3d moments;
  if (rm.size() == kMoments) {
    for (int i = 0; i < kMoments; ++i)
      moments(i / kMomentsSide, i % kMomentsSide) = rm[static_cast<std::size_t>(i)];
  } else {
    Eigen::Matrix2d two;
    for (int i = 0; i < kOldMoments; ++i)
      two(i / kOldMomentsSide, i % kOldMomentsSide) = rm[static_cast<std::size_t>(i)];
    moments = estimators::MomentsFromTwoRegressors(two);
  }
  const auto blocks = static_cast<std::uint64_t>(t["resistance_blocks"].value_or<std::int64_t>(0));
  const auto hx = [&](std::size_t j) {
    Eigen::Vector4d v;
    for (std::size_t i = 0; i < kIdentStates; ++i)
      v(static_cast<Eigen::Index>(i)) = rx[kIdentStates * j + i];
    return v;
  };
  const auto hp = [&](std::size_t j) {
    Eigen::Matrix4d m;
    for (std::size_t i = 0; i < kIdentCovariance; ++i) {
      m(static_cast<Eigen::Index>(i / kIdentStates), static_cast<Eigen::Index>(i % kIdentStates)) =
          rp[kIdentCovariance * j + i];
    }
    return m;
  };
  if (version == 1) {
    out = estimators::StateFromSingleFilter(hx(0), hp(0), moments, blocks,
                                            t["resistance_rejections"].value_or(0), config);
  } else {
    for (std::size_t j = 0; j < hypotheses_count; ++j) {
      auto& h = out.hypotheses[j];
      h.x = hx(j);
      h.p = hp(j);
      h.probability = rprob[j];
      // Rejection counts are small integers; anything else is damage.
      const double rej = rrej[j];
      ok = ok && rej >= 0.0 && rej <= 1e6 && rej == std::floor(rej);
      h.consecutive_rejections = ok ? static_cast<int>(rej) : 0;
    }
    out.moments = moments;
    out.blocks = blocks;
    std::vector<double> anchor;
    if (Numbers(t, "resistance_anchor", kIdentStates, anchor)) {
      out.anchor = Eigen::Map<const Eigen::Vector4d>(anchor.data());
      out.anchor_valid = true;
      // Damaged values are refused by the identifier's Restore (finite, drift_ohm >= 0).
      out.drift_V = t["resistance_drift_V"].value_or(kNaN);
      out.drift_ohm = t["resistance_drift_ohm"].value_or(kNaN);
    }
  }
  return ok;
}

/// The disturbance-state filter's saved state into `s` when its size fits `count` states (another
/// size: saved by another configuration, left out; the nodes are restored alone). False when it
/// fits but is damaged (a value that is not a finite number).
bool ReadDisturbances(const toml::table& t, int count, PumpSavedState& s) {
  const toml::array* x = t["disturbance_x"].as_array();
  const toml::array* c = t["disturbance_s"].as_array();
  const auto n = static_cast<std::size_t>(count);
  if (!x || !c || count <= 0 || x->size() != n || c->size() != n * n) return true;
  std::vector<double> vx, vs;
  if (!Numbers(t, "disturbance_x", n, vx) || !Numbers(t, "disturbance_s", n * n, vs)) return false;
  s.observer_x = Eigen::Map<const Eigen::VectorXd>(vx.data(), count);
  s.observer_s =
      Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
          vs.data(), count, count);
  s.cold_started = t["disturbance_cold_started"].value_or(false);
  if (const auto* law = t["disturbance_magnet_law_given_up_per_K"].as_floating_point()) {
    if (!std::isfinite(law->get())) return false;
    s.magnet_law_given_up_per_K = law->get();
  }
  if (t["disturbance_frame_sensor_lag_s"]) {  // present: two numbers, else damaged
    std::vector<double> lag;
    if (!Numbers(t, "disturbance_frame_sensor_lag_s", 2, lag)) return false;
    s.taken_sensor_lag_s = lag[0];
    s.taken_over_configured_lag_s = lag[1];
  }
  if (t["disturbance_model_losses_sd_rel"]) {  // present: a positive number, else damaged
    const auto sd = t["disturbance_model_losses_sd_rel"].value<double>();
    if (!sd || !(*sd > 0.0) || !std::isfinite(*sd)) return false;
    s.losses_sd_rel = *sd;
  }
  return true;
}

}  // namespace

std::string Gateway::SaveState() const {
  toml::table root;
  // Version 2: the resistance identifier's two magnet hypotheses (version 1: one filter).
  root.insert("version", 2);
  toml::table pumps;
  for (const auto& p : pumps_) {
    const PumpSavedState s = p->Save();
    // A pump whose filter was just reset has no estimate to save, but its latched trips are.
    const bool estimate = p->snapshot().initialised;
    if (!estimate && s.latched_trips.empty()) continue;
    toml::table t;
    t.insert("model", s.model_name);
    if (estimate) InsertEstimate(s, wall_offset_us_, t);
    // Two parallel arrays (toml++ 3.3 misprints an array of tables nested this deep).
    toml::array trip_nodes, trip_values;
    for (const auto& trip : s.latched_trips) {
      trip_nodes.push_back(trip.node);
      trip_values.push_back(trip.value_degC);
    }
    t.insert("latched_trip_nodes", std::move(trip_nodes));
    t.insert("latched_trip_values_degC", std::move(trip_values));
    pumps.insert(p->config().name, std::move(t));
  }
  root.insert("pump", std::move(pumps));
  std::ostringstream ss;
  ss << "# pumpthermd saved state: written atomically; safe to delete (the daemon starts cold;\n"
     << "# latched trips and clear counters are kept in safety.toml).\n"
     << root << "\n";
  return ss.str();
}

int Gateway::RestoreState(const std::string& text, std::int64_t now_us, std::string* warning) {
  MarkAllDue();  // restored estimates and latched trips go out at the next Advance
  toml::table root;
  try {
    root = toml::parse(std::string_view(text), std::string_view("saved state"));
  } catch (const toml::parse_error& e) {
    *warning = fmt::format("saved state does not parse (line {}): {}; starting cold",
                           e.source().begin.line, e.description());
    return 0;
  }
  // Version 1 (before the identifier's magnet hypotheses) is read too: its one filter
  // becomes both hypotheses, with the prior probabilities.
  const std::int64_t version = root["version"].value_or<std::int64_t>(0);
  if (version != 1 && version != 2) {
    *warning = "saved state has an unknown version; starting cold";
    return 0;
  }
  const std::size_t hypotheses = version == 1 ? 1 : estimators::kMagnetHypotheses;
  int restored = 0;
  std::string ignored;
  std::string relatched;
  const toml::table* pumps = root["pump"].as_table();
  for (auto& pump : pumps_) {
    const toml::table* t = pumps ? (*pumps)[pump->config().name].as_table() : nullptr;
    if (!t) continue;
    auto numbers = [&](const char* key, std::size_t n, std::vector<double>& out) {
      return Numbers(*t, key, n, out);
    };
    const int n = pump->model().StateCount();
    PumpSavedState s;
    s.model_name = (*t)["model"].value_or(std::string());
    // Saved in wall time (it outlives this boot); the pipeline runs on its own clock.
    const std::int64_t saved_wall_us = (*t)["time_us"].value_or<std::int64_t>(0);
    s.time_us = saved_wall_us - wall_offset_us_;
    // Latched trips (absent in files written before they were saved: none latched).
    if (!ReadLatchedTrips(*t, s.latched_trips)) {
      ignored += (ignored.empty() ? "" : ", ") + pump->config().name;
      continue;
    }
    std::vector<double> x, cov, rx, rp, rm, rprob, rrej;
    bool ok = numbers("x_degC", static_cast<std::size_t>(n), x) &&
              numbers("s_K2", static_cast<std::size_t>(n * n), cov) &&
              numbers("resistance_x", kIdentStates * hypotheses, rx) &&
              numbers("resistance_p", kIdentCovariance * hypotheses, rp) &&
              (numbers("resistance_moments", kMoments, rm) ||
               numbers("resistance_moments", kOldMoments, rm)) &&
              saved_wall_us > 0 && s.time_us <= now_us + 60'000'000;
    if (ok && version == 2) {
      ok = numbers("resistance_probability", hypotheses, rprob) &&
           numbers("resistance_rejections", hypotheses, rrej);
    }
    if (ok) {
      s.x_degC = Eigen::Map<const Eigen::VectorXd>(x.data(), n);
      s.s_K2 =
          Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
              cov.data(), n, n);
      s.inputs.speed_rpm = (*t)["inputs"]["speed_rpm"].value_or(0.0);
      s.inputs.id_A = (*t)["inputs"]["id_A"].value_or(0.0);
      s.inputs.iq_A = (*t)["inputs"]["iq_A"].value_or(0.0);
      s.inputs.ambient_degC = (*t)["inputs"]["ambient_degC"].value_or(25.0);
      s.inputs.coolant_degC = (*t)["inputs"]["coolant_degC"].value_or(25.0);
      std::vector<double> offset;
      if (numbers("frame_sensor_offset_K", 3, offset)) {
        s.sensor_offset_K = offset[0];
        s.sensor_offset_sd_K = offset[1];
        s.stepped_offset_K = offset[2];
      } else if ((*t)["frame_sensor_offset_K"]) {
        ok = false;  // present but damaged
      }
      ok = ok && ReadDisturbances(*t, pump->ObserverStateCount(), s);
      ok = ok && ReadIdentifierState(*t, version, {rx, rp, rm, rprob, rrej},
                                     pump->identifier().config(), s.resistance);
      ok = ok && pump->Restore(s, std::max(now_us, s.time_us));
    }
    if (ok) {
      ++restored;
      continue;
    }
    ignored += (ignored.empty() ? "" : ", ") + pump->config().name;
    // The filter starts cold, but a latched trip must survive every restart path (a clock far
    // behind the saved time, a damaged filter state, a pump saved while its filter was reset).
    if (!s.latched_trips.empty() && pump->RestoreLatchedTrips(s, now_us)) {
      relatched += fmt::format("{}{} ({} trip(s))", relatched.empty() ? "" : ", ",
                               pump->config().name, s.latched_trips.size());
    }
  }
  if (!ignored.empty()) {
    *warning = fmt::format(
        "saved state of pump(s) {} does not fit the configuration or is damaged; "
        "they start cold",
        ignored);
    if (!relatched.empty()) *warning += fmt::format("; latched again: {}", relatched);
  }
  return restored;
}

}  // namespace pumptherm::daemon
