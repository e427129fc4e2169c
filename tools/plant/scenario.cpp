#include "tools/plant/scenario.hpp"

#include <fmt/core.h>
#include <toml++/toml.h>

#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <optional>
#include <set>

namespace pumptherm::plant {
namespace {

int LineOf(const toml::node& n) { return static_cast<int>(n.source().begin.line); }

[[noreturn]] void Fail(const std::string& source, int line, std::string_view key,
                       const std::string& what) {
  throw ScenarioError(fmt::format("{}:{}: {}: {}", source, line, key, what));
}

/// Rejects keys of `table` not in `allowed` (a misspelt key must not fall back to a default).
void CheckKeys(const toml::table& table, std::initializer_list<std::string_view> allowed,
               const std::string& source, std::string_view where) {
  for (const auto& [key, value] : table) {
    if (std::find(allowed.begin(), allowed.end(), key.str()) == allowed.end()) {
      Fail(source, LineOf(value), fmt::format("{}{}", where, key.str()), "unknown key");
    }
  }
}

/// Reads keys of one table, falling back to a defaults table; errors name the line and key.
class Reader {
 public:
  Reader(const toml::table* primary, const toml::table* fallback, std::string source,
         std::string prefix, int line)
      : primary_(primary),
        fallback_(fallback),
        source_(std::move(source)),
        prefix_(std::move(prefix)),
        line_(line) {}

  const toml::node* Find(std::string_view key) const {
    if (primary_ != nullptr) {
      if (const toml::node* n = primary_->get(key)) return n;
    }
    if (fallback_ != nullptr) return fallback_->get(key);
    return nullptr;
  }

  double Number(std::string_view key, double fallback, double min = -1e300,
                double max = 1e300) const {
    const toml::node* n = Find(key);
    if (n == nullptr) return fallback;
    std::optional<double> v = n->value<double>();
    if (!v || !std::isfinite(*v)) Fail(source_, LineOf(*n), Key(key), "expected a finite number");
    if (*v < min || *v > max) {
      Fail(source_, LineOf(*n), Key(key), fmt::format("{} is outside [{}, {}]", *v, min, max));
    }
    return *v;
  }

  double Positive(std::string_view key, double fallback) const {
    const double v = Number(key, fallback);
    if (!(v > 0.0)) {
      const toml::node* n = Find(key);
      Fail(source_, n ? LineOf(*n) : line_, Key(key), "must be positive");
    }
    return v;
  }

  std::string String(std::string_view key, std::string fallback) const {
    const toml::node* n = Find(key);
    if (n == nullptr) return fallback;
    std::optional<std::string> v = n->value<std::string>();
    if (!v) Fail(source_, LineOf(*n), Key(key), "expected a string");
    return *v;
  }

  bool Bool(std::string_view key, bool fallback) const {
    const toml::node* n = Find(key);
    if (n == nullptr) return fallback;
    std::optional<bool> v = n->value<bool>();
    if (!v) Fail(source_, LineOf(*n), Key(key), "expected true or false");
    return *v;
  }

  std::int64_t Integer(std::string_view key, std::int64_t fallback, std::int64_t min,
                       std::int64_t max) const {
    const toml::node* n = Find(key);
    if (n == nullptr) return fallback;
    std::optional<std::int64_t> v = n->as_integer() ? n->value<std::int64_t>() : std::nullopt;
    if (!v) Fail(source_, LineOf(*n), Key(key), "expected an integer");
    if (*v < min || *v > max) {
      Fail(source_, LineOf(*n), Key(key), fmt::format("{} is outside [{}, {}]", *v, min, max));
    }
    return *v;
  }

  std::string Key(std::string_view key) const { return prefix_ + std::string(key); }
  int line() const { return line_; }

 private:
  const toml::table* primary_;
  const toml::table* fallback_;
  std::string source_;
  std::string prefix_;
  int line_;
};

const toml::table* SubTable(const toml::table* t, std::string_view key, const std::string& source,
                            std::string_view where) {
  if (t == nullptr) return nullptr;
  const toml::node* n = t->get(key);
  if (n == nullptr) return nullptr;
  if (!n->is_table()) Fail(source, LineOf(*n), fmt::format("{}{}", where, key), "expected a table");
  return n->as_table();
}

std::vector<Segment> ParseSegments(const toml::node& node, const std::string& source,
                                   const std::string& where) {
  const toml::array* arr = node.as_array();
  if (arr == nullptr || arr->empty()) {
    Fail(source, LineOf(node), where, "expected a non-empty array of segment tables");
  }
  std::vector<Segment> out;
  for (std::size_t i = 0; i < arr->size(); ++i) {
    const toml::table* t = (*arr)[i].as_table();
    const std::string at = fmt::format("{}[{}].", where, i);
    if (t == nullptr) Fail(source, LineOf((*arr)[i]), at, "expected a table");
    CheckKeys(*t, {"duration_s", "speed_rpm", "iq_A", "iq_end_A", "id_A", "ambient_C", "step"},
              source, at);
    Reader r(t, nullptr, source, at, LineOf(*t));
    Segment s;
    s.line = LineOf(*t);
    if (t->get("duration_s") == nullptr) Fail(source, s.line, at + "duration_s", "missing");
    s.duration_s = r.Positive("duration_s", 0.0);
    s.speed_rpm = r.Number("speed_rpm", kNotGiven, 0.0, 200000.0);
    s.iq_A = r.Number("iq_A", 0.0, -1000.0, 1000.0);
    s.iq_end_A = r.Number("iq_end_A", kNotGiven, -1000.0, 1000.0);
    s.id_A = r.Number("id_A", 0.0, -1000.0, 1000.0);
    s.ambient_degC = r.Number("ambient_C", kNotGiven, -60.0, 200.0);
    s.step = r.Bool("step", false);
    out.push_back(s);
  }
  return out;
}

TemperatureSensorSpec ParseSensor(const toml::table* pump, const toml::table* defaults,
                                  std::string_view key, const std::string& source,
                                  const std::string& where, TemperatureSensorSpec spec,
                                  bool with_node) {
  const toml::table* p = SubTable(pump, key, source, where);
  const toml::table* d = SubTable(defaults, key, source, "defaults.");
  const std::string at = fmt::format("{}{}.", where, key);
  for (const toml::table* t : {p, d}) {
    if (t == nullptr) continue;
    if (with_node) {
      CheckKeys(*t, {"node", "noise_sd_K", "accuracy_K", "offset_K", "resolution_K", "lag_s"},
                source, at);
    } else {
      CheckKeys(*t, {"noise_sd_K", "accuracy_K", "offset_K", "resolution_K", "lag_s"}, source, at);
    }
  }
  Reader r(p, d, source, at, 0);
  if (with_node) spec.node = r.String("node", spec.node);
  spec.noise_sd_K = r.Number("noise_sd_K", spec.noise_sd_K, 0.0, 100.0);
  spec.accuracy_K = r.Number("accuracy_K", spec.accuracy_K, 0.0, 100.0);
  spec.offset_K = r.Number("offset_K", spec.offset_K, -100.0, 100.0);
  spec.resolution_K = r.Number("resolution_K", spec.resolution_K, 0.0, 100.0);
  spec.lag_s = r.Number("lag_s", spec.lag_s, 0.0, 1e6);
  return spec;
}

DriveSpec ParseDrive(const toml::table* pump, const toml::table* defaults,
                     const std::string& source, const std::string& where) {
  const toml::table* p = SubTable(pump, "drive", source, where);
  const toml::table* d = SubTable(defaults, "drive", source, "defaults.");
  const std::string at = where + "drive.";
  for (const toml::table* t : {p, d}) {
    if (t == nullptr) continue;
    CheckKeys(*t,
              {"current_response_s", "current_noise_A", "current_range_A", "phase_offset_A",
               "voltage_noise_V", "dc_link_V", "dc_link_noise_V", "speed_noise_rpm", "dead_time_V",
               "dead_time_knee_A", "magnet_node", "flux_temperature_coefficient_per_K",
               "speed_ripple_rpm", "speed_ripple_hz"},
              source, at);
  }
  Reader r(p, d, source, at, 0);
  DriveSpec s;
  s.current_response_s = r.Positive("current_response_s", s.current_response_s);
  s.current_noise_A = r.Number("current_noise_A", s.current_noise_A, 0.0, 100.0);
  s.current_range_A = r.Positive("current_range_A", s.current_range_A);
  s.phase_offset_A = r.Number("phase_offset_A", s.phase_offset_A, 0.0, 100.0);
  s.voltage_noise_V = r.Number("voltage_noise_V", s.voltage_noise_V, 0.0, 100.0);
  s.dc_link_V = r.Positive("dc_link_V", s.dc_link_V);
  s.dc_link_noise_V = r.Number("dc_link_noise_V", s.dc_link_noise_V, 0.0, 100.0);
  s.speed_noise_rpm = r.Number("speed_noise_rpm", s.speed_noise_rpm, 0.0, 1e4);
  s.dead_time_V = r.Number("dead_time_V", s.dead_time_V, 0.0, 10.0);
  s.dead_time_knee_A = r.Positive("dead_time_knee_A", s.dead_time_knee_A);
  s.magnet_node = r.String("magnet_node", s.magnet_node);
  s.flux_temperature_coefficient_per_K = r.Number("flux_temperature_coefficient_per_K",
                                                  s.flux_temperature_coefficient_per_K, -0.1, 0.1);
  s.speed_ripple_rpm = r.Number("speed_ripple_rpm", s.speed_ripple_rpm, 0.0, 1000.0);
  s.speed_ripple_hz = r.Number("speed_ripple_hz", s.speed_ripple_hz, 0.001, 1000.0);
  return s;
}

// effects = [{ name = "frame_thermal_mass", values = [2700.0] }, ...]: the discrepancy
// workflow's model effects, switched on in the truth (docs/plant-simulator.md).
std::vector<estimators::Effect> ParseEffects(const toml::node& node, const std::string& source,
                                             const std::string& where, double& start_s) {
  const toml::array* arr = node.as_array();
  if (arr == nullptr) Fail(source, LineOf(node), where, "expected an array of tables");
  std::vector<estimators::Effect> out;
  std::set<std::string> seen;
  for (std::size_t i = 0; i < arr->size(); ++i) {
    const toml::table* t = (*arr)[i].as_table();
    const std::string at = fmt::format("{}[{}].", where, i);
    if (t == nullptr) Fail(source, LineOf((*arr)[i]), at, "expected a table");
    CheckKeys(*t, {"name", "values", "start_s"}, source, at);
    Reader r(t, nullptr, source, at, LineOf(*t));
    const double start = r.Number("start_s", 0.0, 0.0, 1e9);
    if (i > 0 && start != start_s) {
      Fail(source, LineOf(*t), at + "start_s",
           fmt::format("{} s, but {} s before: a pump's effects begin together", start, start_s));
    }
    start_s = start;
    const auto name = t->get_as<std::string>("name");
    if (name == nullptr) Fail(source, LineOf(*t), at + "name", "missing (an effect name)");
    const estimators::EffectSpec* spec = estimators::FindEffect(name->get());
    if (spec == nullptr) {
      std::string list;
      for (const auto& e : estimators::EffectVocabulary()) {
        if (!e.sensor) list += (list.empty() ? "" : ", ") + e.name;
      }
      Fail(source, LineOf(*name), at + "name",
           fmt::format("unknown effect '{}' (known: {})", name->get(), list));
    }
    if (spec->sensor) {
      Fail(source, LineOf(*name), at + "name",
           fmt::format(
               "'{}' is a sensor effect: set frame_sensor.lag_s or frame_sensor.offset_K instead",
               spec->name));
    }
    if (!seen.insert(spec->name).second)
      Fail(source, LineOf(*name), at + "name", "effect given twice");
    const toml::array* values = t->get_as<toml::array>("values");
    if (values == nullptr) Fail(source, LineOf(*t), at + "values", "missing (an array of numbers)");
    if (values->size() != spec->parameters.size()) {
      Fail(source, LineOf(*values), at + "values",
           fmt::format("'{}' takes {} value(s)", spec->name, spec->parameters.size()));
    }
    estimators::Effect effect{spec->name, {}, {}};
    for (std::size_t k = 0; k < values->size(); ++k) {
      const std::optional<double> v = (*values)[k].value<double>();
      const estimators::EffectParameterSpec& ps = spec->parameters[k];
      if (!v || !std::isfinite(*v) || *v < ps.lower || *v > ps.upper) {
        Fail(source, LineOf((*values)[k]), fmt::format("{}values[{}]", at, k),
             fmt::format("{} must be a number in [{}, {}]", ps.name, ps.lower, ps.upper));
      }
      effect.values.push_back(*v);
    }
    out.push_back(std::move(effect));
  }
  return out;
}

std::vector<Fault> ParseFaults(const toml::node& node, const std::string& source,
                               const std::string& where) {
  const toml::array* arr = node.as_array();
  if (arr == nullptr) Fail(source, LineOf(node), where, "expected an array of fault tables");
  std::vector<Fault> out;
  for (std::size_t i = 0; i < arr->size(); ++i) {
    const toml::table* t = (*arr)[i].as_table();
    const std::string at = fmt::format("{}[{}].", where, i);
    if (t == nullptr) Fail(source, LineOf((*arr)[i]), at, "expected a table");
    CheckKeys(*t, {"kind", "start_s", "end_s", "probability", "edge", "factor", "offset_K"}, source,
              at);
    Reader r(t, nullptr, source, at, LineOf(*t));
    Fault f;
    f.line = LineOf(*t);
    const std::string kind = r.String("kind", "");
    if (kind == "dropped_frames") {
      f.kind = FaultKind::kDroppedFrames;
    } else if (kind == "stale_sensor") {
      f.kind = FaultKind::kStaleSensor;
    } else if (kind == "stuck_sensor") {
      f.kind = FaultKind::kStuckSensor;
    } else if (kind == "cooling_failure") {
      f.kind = FaultKind::kCoolingFailure;
    } else if (kind == "sensor_offset") {
      f.kind = FaultKind::kSensorOffset;
    } else {
      Fail(source, f.line, at + "kind",
           fmt::format("'{}' is not one of dropped_frames, stale_sensor, stuck_sensor, "
                       "cooling_failure, sensor_offset",
                       kind));
    }
    f.start_s = r.Number("start_s", 0.0, 0.0, 1e9);
    f.end_s = r.Number("end_s", kForever, 0.0, 1e9);
    if (!(f.end_s > f.start_s)) Fail(source, f.line, at + "end_s", "must be after start_s");
    f.probability = r.Number("probability", 1.0, 0.0, 1.0);
    if (f.kind == FaultKind::kCoolingFailure) {
      f.edge = r.String("edge", "");
      if (f.edge.empty())
        Fail(source, f.line, at + "edge", "missing (the edge whose resistance rises)");
      f.factor = r.Positive("factor", 0.0);
    } else if (t->get("edge") || t->get("factor")) {
      Fail(source, f.line, at + "edge", "only a cooling_failure has an edge and a factor");
    }
    if (f.kind == FaultKind::kSensorOffset) {
      f.offset_K = r.Number("offset_K", 0.0, -100.0, 100.0);
      if (!t->get("offset_K")) Fail(source, f.line, at + "offset_K", "missing (the shift, K)");
    } else if (t->get("offset_K")) {
      Fail(source, f.line, at + "offset_K", "only a sensor_offset has an offset_K");
    }
    if (f.kind != FaultKind::kDroppedFrames && t->get("probability")) {
      Fail(source, f.line, at + "probability", "only dropped_frames has a probability");
    }
    out.push_back(f);
  }
  return out;
}

}  // namespace

Scenario ParseScenario(std::string_view toml_text, const std::string& source) {
  toml::table root;
  try {
    root = toml::parse(toml_text, source);
  } catch (const toml::parse_error& e) {
    throw ScenarioError(fmt::format("{}:{}:{}: {}", source, e.source().begin.line,
                                    e.source().begin.column, e.description()));
  }
  CheckKeys(root, {"scenario", "levels", "profile", "defaults", "pump", "bus_off"}, source, "");
  Scenario sc;
  sc.source = source;
  const toml::table* head = SubTable(&root, "scenario", source, "");
  if (head == nullptr) Fail(source, 1, "scenario", "missing table [scenario]");
  CheckKeys(
      *head,
      {"name", "description", "duration_s", "seed", "can_log", "start_epoch_s", "thermal_period_s",
       "truth_period_s", "measured_period_s", "jitter_sd_us", "jitter_max_us"},
      source, "scenario.");
  Reader h(head, nullptr, source, "scenario.", LineOf(*head));
  sc.name = h.String("name", "");
  if (sc.name.empty()) Fail(source, LineOf(*head), "scenario.name", "missing");
  sc.description = h.String("description", "");
  if (head->get("duration_s") == nullptr)
    Fail(source, LineOf(*head), "scenario.duration_s", "missing");
  sc.duration_s = h.Positive("duration_s", 0.0);
  sc.seed =
      static_cast<std::uint64_t>(h.Integer("seed", 1, 0, std::numeric_limits<std::int64_t>::max()));
  sc.can_log = h.Bool("can_log", true);
  sc.start_epoch_us =
      h.Integer("start_epoch_s", sc.start_epoch_us / 1000000, 0, 4102444800LL) * 1000000;
  sc.thermal_period_s = h.Positive("thermal_period_s", sc.thermal_period_s);
  sc.truth_period_s = h.Positive("truth_period_s", sc.truth_period_s);
  sc.measured_period_s = h.Positive("measured_period_s", sc.measured_period_s);
  sc.jitter_sd_us = h.Number("jitter_sd_us", sc.jitter_sd_us, 0.0, 4000.0);
  sc.jitter_max_us = h.Number("jitter_max_us", sc.jitter_max_us, 0.0, 4000.0);
  // Periods must be whole multiples of the step they are counted in.
  const double step_s = sc.can_log ? sc.fast_period_s : sc.thermal_period_s;
  for (auto [key, v] : {std::pair{"thermal_period_s", sc.thermal_period_s},
                        std::pair{"truth_period_s", sc.truth_period_s},
                        std::pair{"measured_period_s", sc.measured_period_s}}) {
    const double ratio = v / step_s;
    if (std::abs(ratio - std::round(ratio)) > 1e-9 || std::round(ratio) < 1.0) {
      Fail(source, LineOf(*head), fmt::format("scenario.{}", key),
           fmt::format("{} s is not a whole multiple of the {} s step", v, step_s));
    }
  }

  if (const toml::table* lv = SubTable(&root, "levels", source, "")) {
    CheckKeys(*lv, {"node", "warning_C", "trip_C"}, source, "levels.");
    Reader r(lv, nullptr, source, "levels.", LineOf(*lv));
    sc.levels.node = r.String("node", sc.levels.node);
    // The resistance-based winding's name before one name per quantity (docs/daemon.md, "Names").
    if (sc.levels.node == "winding_res") {
      fmt::print(stderr,
                 "warning: {}:{}: levels.node = \"winding_res\" is deprecated: read as \"{}\"\n",
                 source, LineOf(*lv), kWindingResistanceLevel);
      sc.levels.node = kWindingResistanceLevel;
    }
    sc.levels.warning_degC = r.Number("warning_C", sc.levels.warning_degC, -50.0, 1000.0);
    sc.levels.trip_degC = r.Number("trip_C", sc.levels.trip_degC, -50.0, 1000.0);
    if (!(sc.levels.trip_degC > sc.levels.warning_degC)) {
      Fail(source, LineOf(*lv), "levels.trip_C", "must be above warning_C");
    }
  }

  const toml::table* profiles = SubTable(&root, "profile", source, "");
  const toml::table* defaults = SubTable(&root, "defaults", source, "");
  const std::initializer_list<std::string_view> pump_keys = {
      "name",         "node_id",         "count",          "stagger_s",        "interface",
      "model",        "motor",           "motor_r0_scale", "motor_flux_scale", "ambient_C",
      "initial_C",    "process_noise_K", "profile",        "segments",         "faults",
      "frame_sensor", "ambient_sensor",  "drive",          "effects"};
  if (defaults != nullptr) {
    CheckKeys(
        *defaults,
        {"interface", "model", "motor", "motor_r0_scale", "motor_flux_scale", "ambient_C",
         "initial_C", "process_noise_K", "profile", "frame_sensor", "ambient_sensor", "drive"},
        source, "defaults.");
  }
  if (profiles != nullptr) {
    for (const auto& [key, value] : *profiles) {
      const toml::table* p = value.as_table();
      const std::string at = fmt::format("profile.{}.", key.str());
      if (p == nullptr) Fail(source, LineOf(value), at, "expected a table");
      CheckKeys(*p, {"segments", "description", "repeat"}, source, at);
      if (p->get("segments") == nullptr) Fail(source, LineOf(*p), at + "segments", "missing");
    }
  }

  const toml::node* pumps_node = root.get("pump");
  if (pumps_node == nullptr || !pumps_node->is_array_of_tables()) {
    Fail(source, 1, "pump", "missing: at least one [[pump]] table");
  }
  std::set<std::pair<std::string, std::uint32_t>> ids;
  std::set<std::string> names;
  const toml::array& pumps = *pumps_node->as_array();
  for (std::size_t i = 0; i < pumps.size(); ++i) {
    const toml::table& pt = *pumps[i].as_table();
    const std::string at = fmt::format("pump[{}].", i);
    CheckKeys(pt, pump_keys, source, at);
    Reader r(&pt, defaults, source, at, LineOf(pt));
    const std::string name = r.String("name", fmt::format("pump{}", i + 1));
    const auto first_id =
        static_cast<std::uint32_t>(r.Integer("node_id", static_cast<std::int64_t>(i), 0, 15));
    const auto count = static_cast<std::uint32_t>(r.Integer("count", 1, 1, 16));
    if (first_id + count > 16) {
      Fail(source, LineOf(pt), at + "count",
           "node IDs must stay below 16 (the mapping's node_id_limit)");
    }
    const double stagger_s = r.Number("stagger_s", 0.0, 0.0, 1e6);

    PumpSpec base;
    base.line = LineOf(pt);
    base.interface = r.String("interface", base.interface);
    base.model = r.String("model", "");
    if (base.model.empty())
      Fail(source, LineOf(pt), at + "model", "missing (a shipped model name or a path)");
    base.motor = r.String("motor", base.motor);
    // A real motor differs from its datasheet by a few percent (realistic-signals.md).
    base.motor_r0_scale = r.Number("motor_r0_scale", base.motor_r0_scale, 0.5, 2.0);
    base.motor_flux_scale = r.Number("motor_flux_scale", base.motor_flux_scale, 0.5, 2.0);
    base.ambient_degC = r.Number("ambient_C", base.ambient_degC, -60.0, 200.0);
    base.initial_degC = r.Number("initial_C", base.initial_degC, -60.0, 400.0);
    base.process_noise_K = r.Number("process_noise_K", base.process_noise_K, 0.0, 10.0);
    base.frame_sensor =
        ParseSensor(&pt, defaults, "frame_sensor", source, at,
                    TemperatureSensorSpec{"frame", 0.05, 0.35, kNotGiven, 0.1, 30.0}, true);
    base.ambient_sensor =
        ParseSensor(&pt, defaults, "ambient_sensor", source, at,
                    TemperatureSensorSpec{"", 0.05, 0.35, kNotGiven, 0.1, 60.0}, false);
    base.drive = ParseDrive(&pt, defaults, source, at);
    if (const toml::node* seg = pt.get("segments")) {
      if (pt.get("profile"))
        Fail(source, LineOf(*seg), at + "segments", "give either segments or profile");
      base.segments = ParseSegments(*seg, source, at + "segments");
    } else {
      const std::string profile = r.String("profile", "");
      if (profile.empty())
        Fail(source, LineOf(pt), at + "profile", "missing: give a profile name or segments");
      const toml::table* p = profiles ? SubTable(profiles, profile, source, "profile.") : nullptr;
      if (p == nullptr) {
        const toml::node* pn = r.Find("profile");
        Fail(source, pn ? LineOf(*pn) : LineOf(pt), at + "profile",
             fmt::format("no [profile.{}] in the file", profile));
      }
      base.segments =
          ParseSegments(*p->get("segments"), source, fmt::format("profile.{}.segments", profile));
      // repeat = N: the segments N times in a row (a daily cycle over a week).
      Reader pr(p, nullptr, source, fmt::format("profile.{}.", profile), LineOf(*p));
      const auto repeat = static_cast<std::size_t>(pr.Integer("repeat", 1, 1, 100000));
      const std::size_t one = base.segments.size();
      for (std::size_t k = 1; k < repeat; ++k) {
        base.segments.insert(base.segments.end(), base.segments.begin(),
                             base.segments.begin() + static_cast<std::ptrdiff_t>(one));
      }
    }
    if (const toml::node* f = pt.get("faults"))
      base.faults = ParseFaults(*f, source, at + "faults");
    if (const toml::node* e = pt.get("effects"))
      base.effects = ParseEffects(*e, source, at + "effects", base.effects_start_s);
    if (base.effects_start_s > 0.0) {
      for (const Fault& f : base.faults) {
        if (f.kind == FaultKind::kCoolingFailure) {
          Fail(source, f.line, at + "faults",
               "a cooling_failure and effects with a start_s on one pump: the truth switches to "
               "one changed model at a time");
        }
      }
    }

    for (std::uint32_t k = 0; k < count; ++k) {
      PumpSpec p = base;
      p.node_id = first_id + k;
      p.name = count == 1 ? name : fmt::format("{}{:02d}", name, p.node_id);
      if (stagger_s > 0.0 && k > 0) {
        Segment idle;
        idle.duration_s = stagger_s * k;
        idle.speed_rpm = 0.0;
        idle.line = base.line;
        p.segments.insert(p.segments.begin(), idle);
      }
      if (!ids.insert({p.interface, p.node_id}).second) {
        Fail(source, LineOf(pt), at + "node_id",
             fmt::format("node ID {} on {} is used by another pump", p.node_id, p.interface));
      }
      if (!names.insert(p.name).second) {
        Fail(source, LineOf(pt), at + "name", fmt::format("pump name '{}' is used twice", p.name));
      }
      sc.pumps.push_back(std::move(p));
    }
  }

  if (const toml::node* bo = root.get("bus_off")) {
    const toml::array* arr = bo->as_array();
    if (arr == nullptr) Fail(source, LineOf(*bo), "bus_off", "expected [[bus_off]] tables");
    for (std::size_t i = 0; i < arr->size(); ++i) {
      const toml::table* t = (*arr)[i].as_table();
      const std::string at = fmt::format("bus_off[{}].", i);
      if (t == nullptr) Fail(source, LineOf((*arr)[i]), at, "expected a table");
      CheckKeys(*t, {"interface", "start_s", "end_s"}, source, at);
      Reader r(t, nullptr, source, at, LineOf(*t));
      BusOff b;
      b.line = LineOf(*t);
      b.interface = r.String("interface", "");
      if (t->get("start_s") == nullptr || t->get("end_s") == nullptr) {
        Fail(source, b.line, at + "start_s", "start_s and end_s are required");
      }
      b.start_s = r.Number("start_s", 0.0, 0.0, 1e9);
      b.end_s = r.Number("end_s", 0.0, 0.0, 1e9);
      if (!(b.end_s > b.start_s)) Fail(source, b.line, at + "end_s", "must be after start_s");
      sc.bus_offs.push_back(b);
    }
  }
  return sc;
}

}  // namespace pumptherm::plant
