#include "tools/plant/plant.hpp"

#include <fmt/core.h>
#include <toml++/toml.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <numbers>
#include <optional>
#include <random>
#include <sstream>
#include <system_error>

#include "estimators/copper.hpp"
#include "estimators/model_effects.hpp"
#include "estimators/motor.hpp"
#include "estimators/thermal_discretisation.hpp"
#include "estimators/thermal_model.hpp"
#include "protocol/candump_log.hpp"
#include "protocol/codec.hpp"
#include "protocol/dbc.hpp"
#include "protocol/mapping.hpp"
#include "tools/common/csv.hpp"
#include "tools/sim/sensor.hpp"

namespace pumptherm::plant {
namespace {

using estimators::ThermalInputs;
using estimators::ThermalModel;
using protocol::MappingInput;

/// SplitMix64 (Steele, Lea, Flood 2014): independent seeds per pump and stream from one seed.
std::uint64_t Mix(std::uint64_t seed, std::uint64_t a, std::uint64_t b) {
  std::uint64_t z = seed + 0x9e3779b97f4a7c15ULL * (a * 64 + b + 1);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

/// Set points of the load profile at one instant.
struct SetPoint {
  double speed_rpm = 0.0;
  double iq_A = 0.0;
  double id_A = 0.0;
  double ambient_degC = 25.0;
  int drive_state = 0;  ///< DBC DriveState: 0 stopped, 1 accelerating, 2 steady, 3 braking
};

/// Piecewise-linear profile: segment i ramps from the previous end values to its own.
class Profile {
 public:
  explicit Profile(const PumpSpec& p) {
    double t = 0.0, speed = 0.0, amb = p.ambient_degC;
    for (const Segment& s : p.segments) {
      Piece piece;
      piece.t0 = t;
      piece.t1 = t + s.duration_s;
      piece.speed0 = speed;
      piece.speed1 = std::isnan(s.speed_rpm) ? speed : s.speed_rpm;
      piece.amb0 = amb;
      piece.amb1 = std::isnan(s.ambient_degC) ? amb : s.ambient_degC;
      if (s.step) {
        piece.speed0 = piece.speed1;
        piece.amb0 = piece.amb1;
      }
      piece.iq0 = s.iq_A;
      piece.iq1 = std::isnan(s.iq_end_A) ? s.iq_A : s.iq_end_A;
      piece.id = s.id_A;
      pieces_.push_back(piece);
      t = piece.t1;
      speed = piece.speed1;
      amb = piece.amb1;
    }
  }

  SetPoint At(double t) {
    while (index_ + 1 < pieces_.size() && t >= pieces_[index_].t1) ++index_;
    const Piece& p = pieces_[index_];
    SetPoint sp;
    if (t >= p.t1) {  // past the last segment: hold its end values
      sp.speed_rpm = p.speed1;
      sp.ambient_degC = p.amb1;
      sp.iq_A = p.iq1;
    } else {
      const double f = (t - p.t0) / (p.t1 - p.t0);
      sp.speed_rpm = p.speed0 + f * (p.speed1 - p.speed0);
      sp.ambient_degC = p.amb0 + f * (p.amb1 - p.amb0);
      sp.iq_A = p.iq0 + f * (p.iq1 - p.iq0);
    }
    sp.id_A = p.id;
    if (t < p.t1 && p.speed1 > p.speed0) {
      sp.drive_state = 1;
    } else if (t < p.t1 && p.speed1 < p.speed0) {
      sp.drive_state = 3;
    } else {
      sp.drive_state = sp.speed_rpm > 0.0 ? 2 : 0;
    }
    return sp;
  }

 private:
  struct Piece {
    double t0, t1, speed0, speed1, amb0, amb1, iq0, iq1, id;
  };
  std::vector<Piece> pieces_;
  std::size_t index_ = 0;
};

/// One encoded frame waiting to be written in time order.
struct PendingFrame {
  std::int64_t time_us = 0;
  std::uint32_t pump = 0;
  std::uint32_t order = 0;  ///< position within the pump's control step
  protocol::CanFrame frame;
};

bool FrameBefore(const PendingFrame& a, const PendingFrame& b) {
  if (a.time_us != b.time_us) return a.time_us < b.time_us;
  if (a.pump != b.pump) return a.pump < b.pump;
  return a.order < b.order;
}

/// A DBC message prepared for encoding: its codec, CAN ID base and value slots.
struct MessagePlan {
  int message_index = -1;
  const protocol::MessageCodec* codec = nullptr;
  std::vector<double> values;
  int counter_signal = -1;
};

/// Slot of a mapped input: the message it lives in, the signal index and the value rule.
struct InputSlot {
  int message_index = -1;
  int signal_index = -1;
  double scale = 1.0;
  double offset = 0.0;
};

struct PumpState {
  const PumpSpec* spec = nullptr;
  estimators::MotorDescription motor;
  std::vector<std::unique_ptr<ThermalModel>> models;  // [0] healthy; then one per cooling fault
  std::vector<int> model_of_fault;                    // fault index -> models index (or -1)
  int active_model = 0;
  int effects_model = -1;  // the model with effects that begin later (-1: none)
  Eigen::VectorXd x;
  Eigen::VectorXd next;
  estimators::ThermalLinearModel lin;
  std::unique_ptr<estimators::ThermalDiscretiser> disc;
  ThermalInputs held;  // inputs held over the current thermal step (ZOH)
  Eigen::VectorXd winding_weights;
  int magnet_state = -1;
  int frame_node = -1;  // index into Nodes()
  int level_node = -1;  // index into Nodes(), -1 = the winding from resistance
  std::mt19937_64 rng_drive, rng_thermal, rng_bus, rng_jitter;
  std::normal_distribution<double> normal{0.0, 1.0};
  std::uniform_real_distribution<double> uniform{0.0, 1.0};
  std::optional<sim::Sensor> frame_sensor, ambient_sensor;
  std::optional<Profile> profile;
  double iq_A = 0.0, id_A = 0.0;
  double angle_rad = 0.0, offset_phase_rad = 0.0;
  std::int64_t phase_us = 0;
  std::uint32_t fast_counter = 0, status_counter = 0;
  double frame_reading_degC = 0.0, ambient_reading_degC = 0.0;
  double frame_lagged_degC = 0.0;
  bool stuck = false;
  double stuck_degC = 0.0;
  // Latest reported electrical values (for the measured CSV).
  double rep_id_A = 0.0, rep_iq_A = 0.0, rep_speed_rpm = 0.0;
  std::unique_ptr<tools::CsvWriter> truth, measured;
  PumpSummary summary;

  double Noise(double sd) { return sd > 0.0 ? sd * normal(rng_drive) : 0.0; }
  const ThermalModel& model() const { return *models[static_cast<std::size_t>(active_model)]; }
};

std::string FormatNumber(double v) { return fmt::format("{}", v); }

/// The frame layout of a scenario that writes a log: the DBC, its codecs, the mapping, the three
/// messages the plant sends and where each mapped input sits. Filled in place (the plans point
/// into the codecs).
struct FrameLayout {
  std::optional<protocol::Dbc> dbc;
  std::optional<protocol::DbcCodec> codecs;
  std::optional<protocol::SignalMapping> mapping;
  MessagePlan fast_i, fast_u, status;
  std::array<InputSlot, protocol::kMappingInputCount> slots{};

  /// Puts the value `v` of input `in` into `plan` when the mapping places it in that message.
  void Set(MessagePlan& plan, MappingInput in, double v) const {
    const InputSlot& s = slots[static_cast<std::size_t>(in)];
    if (s.message_index != plan.message_index) return;  // mapped to another message
    plan.values[static_cast<std::size_t>(s.signal_index)] = (v - s.offset) / s.scale;
  }
};

void LoadFrameLayout(const PlantResources& res, FrameLayout& layout) {
  std::optional<protocol::Dbc>& dbc = layout.dbc;
  std::optional<protocol::DbcCodec>& codecs = layout.codecs;
  std::optional<protocol::SignalMapping>& mapping = layout.mapping;
  auto& slots = layout.slots;
  try {
    dbc = protocol::ParseDbc(res.dbc.text, res.dbc.source);
    mapping = protocol::ParseMapping(res.mapping.text, res.mapping.source, *dbc, {});
  } catch (const std::exception& e) {
    throw ScenarioError(e.what());
  }
  codecs.emplace(*dbc);
  for (std::size_t i = 0; i < protocol::kMappingInputCount; ++i) {
    if (const auto& ref = mapping->inputs[i]) {
      slots[i] = InputSlot{ref->message_index, ref->signal_index, ref->scale, ref->offset};
    }
  }
  auto plan_of = [&](MappingInput in, std::string_view what) {
    const auto& ref = mapping->input(in);
    if (!ref) {
      throw ScenarioError(fmt::format("{}: the mapping does not bind {}, which the plant sends",
                                      res.mapping.source, what));
    }
    MessagePlan p;
    p.message_index = ref->message_index;
    p.codec = &codecs->message(static_cast<std::size_t>(ref->message_index));
    p.values.assign(p.codec->signal_count(), std::nan(""));
    p.counter_signal =
        dbc->messages[static_cast<std::size_t>(ref->message_index)].FindSignal("RollingCounter");
    return p;
  };
  layout.fast_i = plan_of(MappingInput::kIqA, "iq_A");
  layout.fast_u = plan_of(MappingInput::kUqV, "uq_V");
  layout.status = plan_of(MappingInput::kFrameSensorDegC, "frame_sensor_degC");
}

/// The pump's motor: a preset or a file the scenario names.
estimators::MotorDescription PumpMotor(const PumpSpec& spec, const PlantResources& res,
                                       const std::string& where) {
  try {
    if (!estimators::MotorPresetText(spec.motor).empty())
      return estimators::MotorPreset(spec.motor);
    const LoadedText t = res.motor_file(spec.motor);
    return estimators::ParseMotorDescription(t.text, t.source);
  } catch (const std::exception& e) {
    throw ScenarioError(fmt::format("{}: motor '{}': {}", where, spec.motor, e.what()));
  }
}

/// The pump's truth model (with the scenario's hidden effects added), and the variants its
/// cooling faults switch to.
void LoadTruthModels(PumpState& state, const PumpSpec& spec, const PlantResources& res,
                     const std::string& where) {
  PumpState* ps = &state;
  LoadedText model_text;
  try {
    model_text = res.model(spec.model);
    // Tables the model names are read relative to the model file.
    const std::size_t slash = model_text.source.rfind('/');
    const estimators::ThermalModelFiles files{
        slash == std::string::npos ? std::string(".") : model_text.source.substr(0, slash),
        res.read_file};
    // The true motor's R0 differs from the nameplate: so do its copper losses.
    auto true_copper = [&](LoadedText& t) {
      if (spec.motor_r0_scale == 1.0) return;
      t.text = ScaleCopperLosses(t.text, t.source, spec.motor_r0_scale);
      t.source += fmt::format(" (copper x {})", spec.motor_r0_scale);
    };
    if (!spec.effects.empty() && spec.effects_start_s > 0.0) {
      // Effects that begin later: the model without them until their start, then the one with
      // them (switched to as a cooling fault's model is).
      LoadedText before = model_text;
      true_copper(before);
      ps->models.push_back(
          std::make_unique<ThermalModel>(ThermalModel::Parse(before.text, before.source, files)));
      ps->effects_model = 1;
    }
    if (!spec.effects.empty()) {
      // Hidden effects: the truth is the model with the workflow's effects added.
      model_text.text =
          estimators::ApplyModelEffects(model_text.text, model_text.source, spec.effects);
      for (const auto& e : spec.effects) {
        model_text.source += fmt::format(" +{}", e.name);
      }
    }
    true_copper(model_text);
    ps->models.push_back(std::make_unique<ThermalModel>(
        ThermalModel::Parse(model_text.text, model_text.source, files)));
    for (const Fault& f : spec.faults) {
      if (f.kind != FaultKind::kCoolingFailure) {
        ps->model_of_fault.push_back(-1);
        continue;
      }
      const std::string scaled =
          ScaleEdgeResistance(model_text.text, model_text.source, f.edge, f.factor);
      ps->models.push_back(std::make_unique<ThermalModel>(ThermalModel::Parse(
          scaled, fmt::format("{} (edge {} x {})", model_text.source, f.edge, f.factor), files)));
      ps->model_of_fault.push_back(static_cast<int>(ps->models.size()) - 1);
    }
  } catch (const std::exception& e) {
    throw ScenarioError(fmt::format("{}: model '{}': {}", where, spec.model, e.what()));
  }
}

/// Node index of `name` in `m`; throws ScenarioError listing the nodes.
int NodeIndex(const ThermalModel& m, const std::string& name, const PumpSpec& spec,
              const std::string& where) {
  const auto& nodes = m.Nodes();
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    if (nodes[i].name == name) return static_cast<int>(i);
  }
  std::string list;
  for (const auto& n : nodes) list += (list.empty() ? "" : ", ") + n.name;
  throw ScenarioError(
      fmt::format("{}: model '{}' has no node '{}' (nodes: {})", where, spec.model, name, list));
}

/// Pump `pi` of the scenario at its start: motor, truth models, nodes, random streams, sensors,
/// initial state, and its truth and measured CSV files in `out_dir`.
std::unique_ptr<PumpState> SetUpPump(const Scenario& sc, const PlantResources& res, std::size_t pi,
                                     const std::string& out_dir) {
  namespace fs = std::filesystem;
  const bool electrical = sc.can_log;
  const PumpSpec& spec = sc.pumps[pi];
  auto ps = std::make_unique<PumpState>();
  ps->spec = &spec;
  const std::string where = fmt::format("{}:{}: pump '{}'", sc.source, spec.line, spec.name);
  ps->motor = PumpMotor(spec, res, where);
  // The true motor: the nameplate's R0 and flux scaled as the scenario says.
  ps->motor.copper.r0_ohm *= spec.motor_r0_scale;
  ps->motor.flux_Wb *= spec.motor_flux_scale;
  LoadTruthModels(*ps, spec, res, where);
  const ThermalModel& m = *ps->models[0];
  if (m.UsesCoolant()) {
    throw ScenarioError(
        fmt::format("{}: model '{}' has a coolant boundary; the plant drives only "
                    "'ambient' (map the coolant to ambient in the model file)",
                    where, spec.model));
  }

  ps->frame_node = NodeIndex(m, spec.frame_sensor.node, spec, where);
  if (sc.levels.node != kWindingResistanceLevel)
    ps->level_node = NodeIndex(m, sc.levels.node, spec, where);
  ps->winding_weights = m.WindingWeights();
  if (ps->winding_weights.sum() <= 0.0 &&
      (electrical || sc.levels.node == kWindingResistanceLevel)) {
    throw ScenarioError(
        fmt::format("{}: model '{}' has no temperature-dependent copper loss, so "
                    "it defines no winding temperature",
                    where, spec.model));
  }
  if (!spec.drive.magnet_node.empty()) {
    ps->magnet_state = m.StateIndex(spec.drive.magnet_node);
    if (ps->magnet_state < 0) {
      throw ScenarioError(
          fmt::format("{}: drive.magnet_node '{}' is not a node with heat capacity "
                      "in model '{}'",
                      where, spec.drive.magnet_node, spec.model));
    }
  }
  ps->rng_drive.seed(Mix(sc.seed, pi, 1));
  ps->rng_thermal.seed(Mix(sc.seed, pi, 2));
  ps->rng_bus.seed(Mix(sc.seed, pi, 3));
  ps->rng_jitter.seed(Mix(sc.seed, pi, 4));
  std::mt19937_64 rng_setup(Mix(sc.seed, pi, 5));
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  ps->offset_phase_rad = 2.0 * std::numbers::pi * unit(rng_setup);
  ps->phase_us = static_cast<std::int64_t>(unit(rng_setup) * (sc.fast_period_s * 1e6 - 1000.0));
  auto sensor_config = [&](const TemperatureSensorSpec& s) {
    sim::SensorConfig c;
    c.noise_sd = s.noise_sd_K;
    c.offset = std::isnan(s.offset_K) ? s.accuracy_K * (2.0 * unit(rng_setup) - 1.0) : s.offset_K;
    c.lsb = s.resolution_K;
    c.min = -50.0;  // the DBC's FrameSensor_degC / Ambient_degC range
    c.max = 359.4;
    c.lag_tau_s = s.lag_s;
    return c;
  };
  ps->frame_sensor.emplace(sensor_config(spec.frame_sensor), Mix(sc.seed, pi, 6));
  ps->ambient_sensor.emplace(sensor_config(spec.ambient_sensor), Mix(sc.seed, pi, 7));
  ps->profile.emplace(spec);
  const double x0 = std::isnan(spec.initial_degC) ? spec.ambient_degC : spec.initial_degC;
  ps->x = Eigen::VectorXd::Constant(m.StateCount(), x0);
  ps->next.resize(m.StateCount());
  ps->disc = std::make_unique<estimators::ThermalDiscretiser>(1e-4);
  ps->summary.name = spec.name;
  ps->summary.interface = spec.interface;
  ps->summary.node_id = spec.node_id;
  ps->summary.max_level_node_degC = -1e300;
  for (std::size_t fi = 0; fi < spec.faults.size(); ++fi) {
    const Fault& f = spec.faults[fi];
    if (f.kind == FaultKind::kCoolingFailure && f.start_s <= 0.0)
      ps->active_model = ps->model_of_fault[fi];
  }

  std::vector<std::string> tcols{"time_s", "speed_rpm", "id_A", "iq_A", "ambient_degC"};
  for (const auto& n : m.Nodes()) tcols.push_back(n.name + "_degC");
  tcols.insert(tcols.end(), {"winding_resistance_degC", "resistance_ohm", "flux_Wb"});
  for (const auto& n : m.Nodes()) tcols.push_back("loss_" + n.name + "_W");
  tcols.insert(tcols.end(), {"loss_total_W", "cooling_model", "drive_state"});
  ps->truth = std::make_unique<tools::CsvWriter>(
      (fs::path(out_dir) / (spec.name + ".truth.csv")).string(), tcols);
  ps->measured = std::make_unique<tools::CsvWriter>(
      (fs::path(out_dir) / (spec.name + ".measured.csv")).string(),
      std::vector<std::string>{"time_s", "speed_rpm", "id_A", "iq_A", "ambient_degC",
                               spec.frame_sensor.node + "_degC"});
  return ps;
}

/// summary.json: the scenario and, per pump, what the truth reached and the frames written.
void WriteSummaryJson(const std::string& out_dir, const Scenario& sc, const PlantResult& result) {
  namespace fs = std::filesystem;
  const std::string summary_path = (fs::path(out_dir) / "summary.json").string();
  std::string json = fmt::format(
      "{{\n  \"scenario\": \"{}\",\n  \"seed\": {},\n  \"duration_s\": {},\n  \"log\": \"{}\",\n"
      "  \"frames_written\": {},\n  \"levels\": {{\"node\": \"{}\", \"warning_C\": {}, \"trip_C\": "
      "{}}},\n"
      "  \"pumps\": [\n",
      sc.name, sc.seed, sc.duration_s,
      result.log_path.empty() ? "" : fs::path(result.log_path).filename().string(),
      result.frames_written, sc.levels.node, sc.levels.warning_degC, sc.levels.trip_degC);
  for (std::size_t i = 0; i < result.pumps.size(); ++i) {
    const PumpSummary& s = result.pumps[i];
    auto opt = [](double v) { return v < 0.0 ? std::string("null") : fmt::format("{}", v); };
    std::string above;
    for (const auto& [a, b] : s.above_warning_s) {
      auto at = [](double v) { return v < 0.0 ? std::string("null") : fmt::format("{:.2f}", v); };
      above += fmt::format("{}[{}, {}]", above.empty() ? "" : ", ", at(a), at(b));
    }
    json += fmt::format(
        "    {{\"name\": \"{}\", \"interface\": \"{}\", \"node_id\": {}, \"truth\": "
        "\"{}.truth.csv\", "
        "\"measured\": \"{}.measured.csv\", \"max_C\": {:.3f}, \"max_time_s\": {}, "
        "\"warning_crossed_s\": {}, \"trip_crossed_s\": {}, \"above_warning_s\": [{}], "
        "\"frames_written\": {}, "
        "\"frames_suppressed\": {}}}{}\n",
        s.name, s.interface, s.node_id, s.name, s.name, s.max_level_node_degC, s.max_level_time_s,
        opt(s.warning_crossed_s), opt(s.trip_crossed_s), above, s.frames_written,
        s.frames_suppressed, i + 1 < result.pumps.size() ? "," : "");
  }
  json += "  ]\n}\n";
  std::FILE* f = std::fopen(summary_path.c_str(), "wb");
  if (f == nullptr)
    throw std::system_error(errno, std::generic_category(),
                            fmt::format("opening '{}'", summary_path));
  const bool ok = std::fwrite(json.data(), 1, json.size(), f) == json.size();
  if (std::fclose(f) != 0 || !ok) {
    throw std::system_error(errno, std::generic_category(),
                            fmt::format("writing '{}'", summary_path));
  }
}

/// The drive's current loop, first order towards the set point (`follow`; else it takes the set
/// point at once), and the thermal inputs it makes (the coolant is the ambient).
ThermalInputs FollowSetPoint(PumpState& p, const SetPoint& sp, bool follow, double step_s) {
  if (!follow) {
    p.iq_A = sp.iq_A;
    p.id_A = sp.id_A;
  } else {
    const double a = 1.0 - std::exp(-step_s / p.spec->drive.current_response_s);
    p.iq_A += (sp.iq_A - p.iq_A) * a;
    p.id_A += (sp.id_A - p.id_A) * a;
  }
  ThermalInputs in;
  in.speed_rpm = sp.speed_rpm;
  in.iq_A = p.iq_A;
  in.id_A = p.id_A;
  in.ambient_degC = sp.ambient_degC;
  in.coolant_degC = sp.ambient_degC;
  return in;
}

/// The magnet flux of the truth: the motor's, scaled by the scenario's coefficient relative to
/// the motor's magnet reference (its copper T0 when the motor file states no magnet law).
double TrueFlux_Wb(const PumpState& p) {
  if (p.magnet_state < 0) return p.motor.flux_Wb;
  const double t0_degC = p.motor.magnet.Given() ? p.motor.magnet.t0_degC : p.motor.copper.t0_degC;
  return p.motor.flux_Wb *
         (1.0 + p.spec->drive.flux_temperature_coefficient_per_K * (p.x(p.magnet_state) - t0_degC));
}

/// The faults of a pump active at time `t` (cooling failures switch models at thermal steps).
struct ActiveFaults {
  bool dropped_window = false, stale = false, stuck = false;
  double drop_probability = 0.0;
  double sensor_offset_K = 0.0;
};

/// The frame and ambient sensors read `dt_s` after their last reading (0: the first); a stuck
/// frame sensor holds the reading it had when it stuck; a sensor offset fault shifts the reading.
void SampleSensors(PumpState& p, const ThermalInputs& in, double ambient_degC,
                   const ActiveFaults& faults, double dt_s) {
  const bool stuck_now = faults.stuck;
  const double frame_true = p.model().AllTemperatures_degC(in, p.x)(p.frame_node);
  const double reading = p.frame_sensor->Measure(frame_true, dt_s) + faults.sensor_offset_K;
  p.frame_lagged_degC = p.frame_sensor->lagged();
  if (stuck_now && !p.stuck) p.stuck_degC = p.frame_reading_degC;
  p.stuck = stuck_now;
  if (dt_s == 0.0 && stuck_now) p.stuck_degC = reading;
  p.frame_reading_degC = p.stuck ? p.stuck_degC : reading;
  p.ambient_reading_degC = p.ambient_sensor->Measure(ambient_degC, dt_s);
}

/// What the drive reports besides the currents and speed (those go into PumpState::rep_*).
struct DriveReport {
  double ud_V = 0.0, uq_V = 0.0, dc_link_V = 0.0;
};

/// One control step of the drive at time `t_s`: the true dq voltages (Han 2019 eq. 4, the SPMSM's
/// voltage equations, plus the dead-time voltage) at the true speed (the set point plus the
/// rotor's mechanical ripple), and the reported values with offset ripple, noise and 12-bit
/// quantisation; the reported speed is the drive's estimate, without the mechanical ripple.
/// `first`: no current derivative yet.
DriveReport ReportDrive(PumpState& p, const SetPoint& sp, double t_s, double rs_ohm, double flux_Wb,
                        bool first, double iq_prev_A, double id_prev_A, double step_s) {
  const auto& motor = p.motor;
  const DriveSpec& drive = p.spec->drive;
  const double ripple_rpm =
      sp.speed_rpm > 0.0 && drive.speed_ripple_rpm > 0.0
          ? drive.speed_ripple_rpm * std::sin(2.0 * std::numbers::pi * drive.speed_ripple_hz * t_s)
          : 0.0;
  const double w = estimators::ElectricalSpeed_rad_per_s(motor, sp.speed_rpm + ripple_rpm);
  const double diq = first ? 0.0 : (p.iq_A - iq_prev_A) / step_s;
  const double did = first ? 0.0 : (p.id_A - id_prev_A) / step_s;
  double uq =
      rs_ohm * p.iq_A + motor.inductance_H * diq + w * (motor.inductance_H * p.id_A + flux_Wb);
  double ud = rs_ohm * p.id_A + motor.inductance_H * did - motor.inductance_H * w * p.iq_A;
  if (drive.dead_time_V > 0.0) {
    const double mag = std::hypot(p.id_A, p.iq_A);
    if (mag > 0.0) {
      const double e = drive.dead_time_V * std::tanh(mag / drive.dead_time_knee_A) / mag;
      uq += e * p.iq_A;
      ud += e * p.id_A;
    }
  }
  p.angle_rad = std::fmod(p.angle_rad + w * step_s, 2.0 * std::numbers::pi);
  const double i_lsb = 2.0 * drive.current_range_A / 4096.0;
  const double u_lsb = 2.0 * drive.dc_link_V / 4096.0;
  const double ripple_q = drive.phase_offset_A * std::cos(p.angle_rad + p.offset_phase_rad);
  const double ripple_d = drive.phase_offset_A * std::sin(p.angle_rad + p.offset_phase_rad);
  const double range = drive.current_range_A;
  // The noise draws keep this order: one random stream per pump.
  p.rep_id_A =
      sim::Quantise(p.id_A + ripple_d + p.Noise(drive.current_noise_A), i_lsb, -range, range);
  p.rep_iq_A =
      sim::Quantise(p.iq_A + ripple_q + p.Noise(drive.current_noise_A), i_lsb, -range, range);
  DriveReport r;
  r.ud_V =
      sim::Quantise(ud + p.Noise(drive.voltage_noise_V), u_lsb, -drive.dc_link_V, drive.dc_link_V);
  r.uq_V =
      sim::Quantise(uq + p.Noise(drive.voltage_noise_V), u_lsb, -drive.dc_link_V, drive.dc_link_V);
  p.rep_speed_rpm =
      sp.speed_rpm > 0.0 ? std::max(0.0, sp.speed_rpm + p.Noise(drive.speed_noise_rpm)) : 0.0;
  r.dc_link_V = drive.dc_link_V + p.Noise(drive.dc_link_noise_V);
  return r;
}

/// Winding temperature, resistance and flux of the truth at one step.
struct TruthElectrical {
  double winding_degC, rs_ohm, flux_Wb;
};

/// One row of the truth CSV: inputs, every node's temperature, the electrical truth, each node's
/// loss and their sum, the cooling model in force and the drive state.
void WriteTruthRow(PumpState& p, const ThermalInputs& in, const SetPoint& sp, double t,
                   const TruthElectrical& e) {
  const ThermalModel& m = p.model();
  const Eigen::VectorXd all = m.AllTemperatures_degC(in, p.x);
  const Eigen::VectorXd losses = m.NodeLosses_W(in, p.x);
  std::vector<double> row{t, sp.speed_rpm, p.id_A, p.iq_A, sp.ambient_degC};
  for (Eigen::Index i = 0; i < all.size(); ++i) row.push_back(all(i));
  row.insert(row.end(), {e.winding_degC, e.rs_ohm, e.flux_Wb});
  for (Eigen::Index i = 0; i < losses.size(); ++i) row.push_back(losses(i));
  row.insert(row.end(), {losses.sum(), static_cast<double>(p.active_model),
                         static_cast<double>(sp.drive_state)});
  p.truth->Row(row);
}

ActiveFaults FaultsAt(const PumpSpec& spec, double t) {
  ActiveFaults a;
  for (const Fault& f : spec.faults) {
    if (t < f.start_s || t >= f.end_s) continue;
    switch (f.kind) {
      case FaultKind::kDroppedFrames:
        a.dropped_window = true;
        a.drop_probability = std::max(a.drop_probability, f.probability);
        break;
      case FaultKind::kStaleSensor:
        a.stale = true;
        break;
      case FaultKind::kStuckSensor:
        a.stuck = true;
        break;
      case FaultKind::kSensorOffset:
        a.sensor_offset_K += f.offset_K;
        break;
      case FaultKind::kCoolingFailure:
        break;
    }
  }
  return a;
}

/// Encodes a pump's frames of one control step into `pending` (written in time order later): the
/// current and voltage frames every step, the status frame at the status rate. A frame is dropped
/// while its bus is off or, in a dropped-frames fault, at random; a stale sensor suppresses the
/// status frame.
struct FrameEmitter {
  const Scenario& sc;
  FrameLayout& layout;
  std::vector<PendingFrame>& pending;
  std::int64_t period_us;

  void ControlStep(PumpState& p, std::uint32_t pump, std::int64_t k, double t, const SetPoint& sp,
                   const DriveReport& drive, const ActiveFaults& faults, bool status_tick) {
    const bool off = IsBusOff(p.spec->interface, t);
    const std::int64_t nominal_us = sc.start_epoch_us + k * period_us + p.phase_us;
    const std::uint32_t counter = p.fast_counter;
    p.fast_counter = (p.fast_counter + 1) % 16;
    for (MessagePlan* plan : {&layout.fast_i, &layout.fast_u, &layout.status}) {
      std::fill(plan->values.begin(), plan->values.end(), std::nan(""));
    }
    const double w_reported = estimators::ElectricalSpeed_rad_per_s(p.motor, p.rep_speed_rpm);
    for (MessagePlan* plan : {&layout.fast_i, &layout.fast_u}) {
      layout.Set(*plan, MappingInput::kIdA, p.rep_id_A);
      layout.Set(*plan, MappingInput::kIqA, p.rep_iq_A);
      layout.Set(*plan, MappingInput::kUdV, drive.ud_V);
      layout.Set(*plan, MappingInput::kUqV, drive.uq_V);
      layout.Set(*plan, MappingInput::kSpeedElecRadPerS, w_reported);
    }
    // Frame times: the drive sends I, then U one frame time (about 250 us at 500 kbit/s)
    // later, then the status; jitter never reorders one pump's frames.
    const std::int64_t t_i = nominal_us + Jitter(p);
    const std::int64_t t_u = std::max(t_i + 1, nominal_us + 250 + Jitter(p));
    Emit(p, pump, layout.fast_i, counter, t_i, 0, off, faults);
    Emit(p, pump, layout.fast_u, counter, t_u, 1, off, faults);
    if (!status_tick) return;
    const std::uint32_t status_counter = p.status_counter;
    p.status_counter = (p.status_counter + 1) % 16;
    const std::int64_t t_s = std::max(t_u + 1, nominal_us + 500 + Jitter(p));
    if (faults.stale) {
      ++p.summary.frames_suppressed;
      return;
    }
    layout.Set(layout.status, MappingInput::kSpeedMechRpm, p.rep_speed_rpm);
    layout.Set(layout.status, MappingInput::kDriveState, sp.drive_state);
    layout.Set(layout.status, MappingInput::kFrameSensorDegC, p.frame_reading_degC);
    layout.Set(layout.status, MappingInput::kAmbientDegC, p.ambient_reading_degC);
    layout.Set(layout.status, MappingInput::kDcLinkV, drive.dc_link_V);
    Emit(p, pump, layout.status, status_counter, t_s, 2, off, faults);
  }

 private:
  std::int64_t Jitter(PumpState& p) const {
    const double j = sc.jitter_sd_us * p.normal(p.rng_jitter);
    return static_cast<std::int64_t>(
        std::llround(std::clamp(j, -sc.jitter_max_us, sc.jitter_max_us)));
  }

  bool IsBusOff(const std::string& iface, double t) const {
    for (const BusOff& b : sc.bus_offs) {
      if ((b.interface.empty() || b.interface == iface) && t >= b.start_s && t < b.end_s)
        return true;
    }
    return false;
  }

  void Emit(PumpState& p, std::uint32_t pump, MessagePlan& plan, std::uint32_t counter,
            std::int64_t time_us, std::uint32_t order, bool off, const ActiveFaults& faults) {
    bool drop = off;
    if (!drop && faults.dropped_window) drop = p.uniform(p.rng_bus) < faults.drop_probability;
    if (drop) {
      ++p.summary.frames_suppressed;
      return;
    }
    if (plan.counter_signal >= 0)
      plan.values[static_cast<std::size_t>(plan.counter_signal)] = counter;
    PendingFrame f;
    f.time_us = time_us;
    f.pump = pump;
    f.order = order;
    f.frame.id = layout.mapping->CanId(*layout.dbc, plan.message_index, p.spec->node_id);
    f.frame.extended = plan.codec->extended();
    f.frame.len = static_cast<std::uint8_t>(plan.codec->min_bytes());
    plan.codec->Encode(plan.values, std::span<std::uint8_t>(f.frame.data.data(), f.frame.len));
    pending.push_back(f);
    ++p.summary.frames_written;
  }
};

/// The truth's level node at time `t` into the pump's summary: maximum, first warning and trip
/// crossings, and the intervals above the warning level.
void RecordLevel(PumpSummary& summary, const TruthLevels& levels, double level, double t) {
  if (level > summary.max_level_node_degC) {
    summary.max_level_node_degC = level;
    summary.max_level_time_s = t;
  }
  if (summary.warning_crossed_s < 0.0 && level > levels.warning_degC) summary.warning_crossed_s = t;
  auto& above = summary.above_warning_s;
  const bool was_above = !above.empty() && above.back().second < 0.0;
  if (!was_above && level > levels.warning_degC) above.emplace_back(t, -1.0);
  if (was_above && !(level > levels.warning_degC)) above.back().second = t;
  if (summary.trip_crossed_s < 0.0 && level > levels.trip_degC) summary.trip_crossed_s = t;
}

/// End of a thermal period: one exact zero-order-hold step of the truth with the latched inputs
/// plus process noise; a cooling fault active at `t_next_s` takes effect from the next step.
void AdvanceTruth(PumpState& p, double thermal_dt_s, double t_next_s) {
  const PumpSpec& spec = *p.spec;
  p.model().Linearise(p.held, p.x, p.lin);
  p.disc->Update(p.lin, thermal_dt_s);
  p.disc->Propagate(p.x, p.lin, p.next);
  const double sd = spec.process_noise_K * std::sqrt(thermal_dt_s);
  for (Eigen::Index i = 0; i < p.next.size(); ++i) p.next(i) += sd * p.normal(p.rng_thermal);
  p.x = p.next;
  int model_next = p.effects_model >= 0 && t_next_s >= spec.effects_start_s ? p.effects_model : 0;
  for (std::size_t fi = 0; fi < spec.faults.size(); ++fi) {
    const Fault& f = spec.faults[fi];
    if (f.kind == FaultKind::kCoolingFailure && t_next_s >= f.start_s && t_next_s < f.end_s) {
      model_next = p.model_of_fault[fi];
    }
  }
  if (model_next != p.active_model) {
    p.active_model = model_next;
    p.disc = std::make_unique<estimators::ThermalDiscretiser>(1e-4);
  }
}

}  // namespace

std::string ScaleEdgeResistance(std::string_view model_text, const std::string& source,
                                const std::string& edge, double factor) {
  toml::table root;
  try {
    root = toml::parse(model_text, source);
  } catch (const toml::parse_error& e) {
    throw ScenarioError(fmt::format("{}:{}: {}", source, e.source().begin.line, e.description()));
  }
  toml::array* edges = root["edge"].as_array();
  std::vector<std::string> names;
  if (edges != nullptr) {
    for (toml::node& n : *edges) {
      toml::table* t = n.as_table();
      if (t == nullptr) continue;
      std::string a, b;
      if (const toml::array* between = (*t)["between"].as_array();
          between && between->size() == 2) {
        a = (*between)[0].value_or(std::string{});
        b = (*between)[1].value_or(std::string{});
      }
      const std::string name = (*t)["name"].value_or(a + "-" + b);
      names.push_back(name);
      if (edge != name && edge != a + "-" + b && edge != b + "-" + a) continue;
      toml::node* r = t->get("resistance_K_per_W");
      if (r == nullptr) break;  // the model parser reports the missing key
      if (std::optional<double> v = r->value<double>()) {
        t->insert_or_assign("resistance_K_per_W", *v * factor);
      } else if (std::optional<std::string> s = r->value<std::string>()) {
        t->insert_or_assign("resistance_K_per_W",
                            fmt::format("({}) * {}", *s, FormatNumber(factor)));
      }
      std::ostringstream os;
      os << root;
      return os.str();
    }
  }
  std::string list;
  for (const std::string& n : names) list += (list.empty() ? "" : ", ") + n;
  throw ScenarioError(fmt::format("{}: no edge named '{}' (edges: {})", source, edge, list));
}

std::string ScaleCopperLosses(std::string_view model_text, const std::string& source,
                              double factor) {
  toml::table root;
  try {
    root = toml::parse(model_text, source);
  } catch (const toml::parse_error& e) {
    throw ScenarioError(fmt::format("{}:{}: {}", source, e.source().begin.line, e.description()));
  }
  int scaled = 0;
  if (toml::array* losses = root["loss"].as_array()) {
    for (toml::node& n : *losses) {
      toml::table* t = n.as_table();
      // A copper loss is the one with a temperature coefficient (docs/thermal-model.md).
      if (t == nullptr || t->get("temperature_coefficient_per_K") == nullptr) continue;
      toml::node* power = t->get("power_W");
      if (power == nullptr) continue;  // the model parser reports the missing key
      if (std::optional<double> v = power->value<double>()) {
        t->insert_or_assign("power_W", *v * factor);
      } else if (std::optional<std::string> e = power->value<std::string>()) {
        t->insert_or_assign("power_W", fmt::format("({}) * {}", *e, FormatNumber(factor)));
      }
      ++scaled;
    }
  }
  if (scaled == 0) {
    throw ScenarioError(fmt::format(
        "{}: no copper loss (a [[loss]] with temperature_coefficient_per_K) to scale", source));
  }
  std::ostringstream os;
  os << root;
  return os.str();
}

PlantResult RunPlant(const Scenario& sc, const PlantResources& res, const std::string& out_dir,
                     const std::function<void(double)>& progress) {
  namespace fs = std::filesystem;
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (ec) throw std::system_error(ec, fmt::format("creating output directory '{}'", out_dir));

  // Frame layout, only for scenarios that write a log.
  FrameLayout layout;
  if (sc.can_log) LoadFrameLayout(res, layout);

  // Pumps.
  const bool electrical = sc.can_log;
  const double step_s = electrical ? sc.fast_period_s : sc.thermal_period_s;
  const auto steps =
      static_cast<std::int64_t>(std::llround(std::ceil(sc.duration_s / step_s - 1e-9)));
  const auto per = [&](double period) {
    return static_cast<std::int64_t>(std::llround(period / step_s));
  };
  const std::int64_t thermal_every = electrical ? per(sc.thermal_period_s) : 1;
  const std::int64_t status_every = per(sc.status_period_s);
  const std::int64_t truth_every = per(sc.truth_period_s);
  const std::int64_t measured_every = per(sc.measured_period_s);
  const double thermal_dt_s = static_cast<double>(thermal_every) * step_s;

  std::vector<std::unique_ptr<PumpState>> pumps;
  for (std::size_t pi = 0; pi < sc.pumps.size(); ++pi)
    pumps.push_back(SetUpPump(sc, res, pi, out_dir));

  // Log file.
  PlantResult result;
  std::FILE* log = nullptr;
  if (electrical) {
    result.log_path = (fs::path(out_dir) / (sc.name + ".log")).string();
    log = std::fopen(result.log_path.c_str(), "wb");
    if (log == nullptr) {
      throw std::system_error(errno, std::generic_category(),
                              fmt::format("opening '{}'", result.log_path));
    }
  }
  struct LogCloser {
    std::FILE*& f;
    ~LogCloser() {
      if (f != nullptr) std::fclose(f);
    }
  } closer{log};
  std::vector<PendingFrame> pending;
  std::string line;
  // The lines of one flush are formatted into one buffer (its capacity kept) and written at once.
  auto write_until = [&](std::int64_t limit_us) {
    std::sort(pending.begin(), pending.end(), FrameBefore);
    std::size_t n = 0;
    line.clear();
    while (n < pending.size() && pending[n].time_us < limit_us) {
      const PendingFrame& f = pending[n];
      protocol::AppendCandumpLine(line, f.time_us, sc.pumps[f.pump].interface, f.frame);
      line += '\n';
      ++n;
    }
    if (std::fwrite(line.data(), 1, line.size(), log) != line.size()) {
      throw std::system_error(errno, std::generic_category(),
                              fmt::format("writing '{}'", result.log_path));
    }
    pending.erase(pending.begin(), pending.begin() + static_cast<std::ptrdiff_t>(n));
    result.frames_written += n;
  };

  const std::int64_t period_us = std::llround(sc.fast_period_s * 1e6);
  const auto jitter_max_us = static_cast<std::int64_t>(sc.jitter_max_us);
  FrameEmitter frames{sc, layout, pending, period_us};

  int last_percent = -1;
  for (std::int64_t k = 0; k < steps; ++k) {
    const double t = static_cast<double>(k) * step_s;
    for (std::size_t pi = 0; pi < pumps.size(); ++pi) {
      PumpState& p = *pumps[pi];
      const PumpSpec& spec = *p.spec;
      const SetPoint sp = p.profile->At(t);

      const ActiveFaults faults = FaultsAt(spec, t);

      // Thermal truth: one exact ZOH step at the end of each thermal period (below); at its
      // start the inputs are latched.
      const ThermalModel& m = p.model();
      const double iq_prev = p.iq_A, id_prev = p.id_A;
      const ThermalInputs in = FollowSetPoint(p, sp, electrical && k > 0, step_s);
      if (k % thermal_every == 0) p.held = in;

      const double winding_degC = p.winding_weights.dot(p.x);
      const double rs_ohm = estimators::ResistanceAt(p.motor.copper, winding_degC);
      const double flux_Wb = TrueFlux_Wb(p);

      // Sensors, sampled at the status rate (every thermal step in a thermal-only run).
      if (!electrical || k % status_every == 0) {
        SampleSensors(p, in, sp.ambient_degC, faults,
                      k == 0       ? 0.0
                      : electrical ? sc.status_period_s
                                   : step_s);
      }

      if (electrical) {
        const DriveReport drive =
            ReportDrive(p, sp, t, rs_ohm, flux_Wb, k == 0, iq_prev, id_prev, step_s);
        frames.ControlStep(p, static_cast<std::uint32_t>(pi), k, t, sp, drive, faults,
                           k % status_every == 0);
      } else {
        p.rep_id_A = sp.id_A;
        p.rep_iq_A = sp.iq_A;
        p.rep_speed_rpm = sp.speed_rpm;
      }

      // Truth level summary (every thermal step).
      if (k % thermal_every == 0) {
        const double level =
            p.level_node < 0 ? winding_degC : m.AllTemperatures_degC(in, p.x)(p.level_node);
        RecordLevel(p.summary, sc.levels, level, t);
      }
      if (k % truth_every == 0) WriteTruthRow(p, in, sp, t, {winding_degC, rs_ohm, flux_Wb});
      if (k % measured_every == 0) {
        p.measured->Row({t, p.rep_speed_rpm, p.rep_id_A, p.rep_iq_A, p.ambient_reading_degC,
                         faults.stale ? std::nan("") : p.frame_reading_degC});
      }

      // End of a thermal period: advance the truth with the latched inputs.
      if ((k + 1) % thermal_every == 0)
        AdvanceTruth(p, thermal_dt_s, static_cast<double>(k + 1) * step_s);
    }
    if (electrical && (k % 100 == 99 || k + 1 == steps)) {
      write_until(k + 1 == steps ? INT64_MAX
                                 : sc.start_epoch_us + (k + 1) * period_us - jitter_max_us - 1);
    }
    if (progress) {
      const int percent = static_cast<int>(100 * (k + 1) / steps);
      if (percent != last_percent) {
        last_percent = percent;
        progress(static_cast<double>(k + 1) / static_cast<double>(steps));
      }
    }
  }

  for (auto& p : pumps) {
    p->truth->Close();
    p->measured->Close();
    result.pumps.push_back(p->summary);
  }
  if (log != nullptr) {
    const int rc = std::fclose(log);
    log = nullptr;
    if (rc != 0)
      throw std::system_error(errno, std::generic_category(),
                              fmt::format("closing '{}'", result.log_path));
  }

  WriteSummaryJson(out_dir, sc, result);
  return result;
}

}  // namespace pumptherm::plant
