#include "estimators/motor.hpp"

#include <fmt/core.h>
#include <toml++/toml.h>

#include <cmath>
#include <numbers>
#include <optional>

namespace pumptherm::estimators {
namespace {

// Kept identical to estimators/motors/han2019-tmp.toml (motor_description_test checks it).
constexpr std::string_view kHan2019Tmp =
    R"(# Motor of the self-built maglev turbo-molecular pump of Han, Xiong, Mao, "Estimation of
# temperature in turbo-molecular pump based on motor resistance online identification",
# Vacuum 169 (2019) 108935, Table 1. Format: docs/resistance-identification.md.
name = "han2019-tmp"
pole_pairs = 1
rated_speed_rpm = 21000.0
flux_Wb = 0.0182
inductance_H = 0.24e-3

[resistance]
# Table 1 gives 0.28 ohm as the "static value" (the winding at room temperature with the motor
# stopped); the paper's room temperature during the Pt100 calibration was 27.2 degC, used here.
r0_ohm = 0.28
t0_degC = 27.2
# Han 2019 section 3.1 (eq. 2): alpha_Cu = 4.1e-3 1/degC.
alpha_per_K = 4.1e-3
plausible_min_degC = -20.0
plausible_max_degC = 180.0

[drive]
# The drive's current limit: the largest magnitude of the dq current vector (the phase currents'
# peak) it lets the motor draw. The paper does not give it: assumed 15 A, 900 W of shaft power at
# the rated speed (1.5 psi_f w_r iq) and the heaviest load of the plant's scenarios. While a
# pump's telemetry is silent, the alarms assume the motor may draw it (docs/daemon.md).
max_current_A = 15.0
# The step of the uq the drive reports (its ADC or command resolution, codes at integer multiples
# of it). With it the identifier removes the quantisation bias of its block means
# (docs/resistance-identification.md); the paper does not give it. For example, 12 bits over a
# +/-48 V DC link:
# uq_resolution_V = 0.0234375
# The drive's voltage error from dead time, if known (compensated before identification):
# u_err tanh(|i| / knee) along the current vector; knee 0 gives u_err sign(i).
# voltage_error_V = 0.15
# voltage_error_knee_A = 0.5

[magnet]
# The paper gives psi_f (Table 1) but neither the magnet grade nor the temperature of the
# measurement: assumed sintered NdFeB (reversible temperature coefficient of the remanence
# -0.09 to -0.13 %/K in the makers' sheets, docs/virtual-sensor.md) with psi_f at the same room
# temperature as R0.
t0_degC = 27.2
flux_temperature_coefficient_per_K = -1.0e-3
)";

std::string Where(std::string_view source, const toml::source_region& region) {
  if (region.begin.line == 0) return std::string(source);
  return fmt::format("{}:{}", source, region.begin.line);
}

// Reads a number (integer or float) at `key` of `table`; `path` is the dotted key for errors.
std::optional<double> Number(const toml::table& table, std::string_view key, std::string_view path,
                             std::string_view source, bool required) {
  const toml::node* node = table.get(key);
  if (node == nullptr) {
    if (!required) return std::nullopt;
    throw MotorDescriptionError(
        fmt::format("{}:{}: missing key '{}'", source, table.source().begin.line, path));
  }
  if (const auto v = node->value<double>(); v && node->is_number()) {
    if (!std::isfinite(*v)) {
      throw MotorDescriptionError(
          fmt::format("{}: key '{}' is not a finite number", Where(source, node->source()), path));
    }
    return *v;
  }
  throw MotorDescriptionError(
      fmt::format("{}: key '{}' must be a number", Where(source, node->source()), path));
}

void RejectUnknownKeys(const toml::table& table, std::initializer_list<std::string_view> known,
                       std::string_view prefix, std::string_view source) {
  for (const auto& [key, node] : table) {
    bool ok = false;
    for (auto k : known) ok = ok || key.str() == k;
    if (!ok) {
      throw MotorDescriptionError(
          fmt::format("{}: unknown key '{}{}'", Where(source, node.source()), prefix, key.str()));
    }
  }
}

void RequirePositive(double value, const toml::table& table, std::string_view key,
                     std::string_view path, std::string_view source) {
  if (value > 0.0) return;
  const toml::node* node = table.get(key);
  throw MotorDescriptionError(fmt::format("{}: key '{}' must be positive, got {}",
                                          Where(source, node->source()), path, value));
}

void ParseMagnetLaw(const toml::node& node, std::string_view source, MotorDescription& m) {
  if (!node.is_table()) {
    throw MotorDescriptionError(
        fmt::format("{}: key 'magnet' must be a table", Where(source, node.source())));
  }
  const toml::table& magnet = *node.as_table();
  RejectUnknownKeys(magnet, {"t0_degC", "flux_temperature_coefficient_per_K"}, "magnet.", source);
  m.magnet.t0_degC = *Number(magnet, "t0_degC", "magnet.t0_degC", source, true);
  const double beta = *Number(magnet, "flux_temperature_coefficient_per_K",
                              "magnet.flux_temperature_coefficient_per_K", source, true);
  // Ferrite about -0.2 %/K, NdFeB about -0.1, SmCo about -0.03: a flux that rises with
  // temperature or barely moves is no magnet law (the temperature would be noise / beta).
  if (!(beta >= -5e-3 && beta <= -1e-5)) {
    throw MotorDescriptionError(fmt::format(
        "{}: key 'magnet.flux_temperature_coefficient_per_K' must be within [-0.005, -0.00001] per "
        "K "
        "(NdFeB about -1e-3, SmCo about -3e-4), got {}",
        Where(source, magnet.get("flux_temperature_coefficient_per_K")->source()), beta));
  }
  m.magnet.flux_temperature_coefficient_per_K = beta;
}

}  // namespace

namespace {

// The inverter's voltage error along the current vector (dead time, switch drops):
// u_err tanh(|i| / knee) i / |i|, the sign(i) term when the knee is 0. Both keys or neither.
void ParseVoltageError(const toml::table& drive, std::string_view source, MotorDescription& m) {
  const auto u = Number(drive, "voltage_error_V", "drive.voltage_error_V", source, false);
  const auto knee =
      Number(drive, "voltage_error_knee_A", "drive.voltage_error_knee_A", source, false);
  if (knee && !u) {
    throw MotorDescriptionError(
        fmt::format("{}: key 'drive.voltage_error_knee_A' needs 'drive.voltage_error_V'",
                    Where(source, drive.get("voltage_error_knee_A")->source())));
  }
  if (!u) return;
  // A few volts is a broken drive, not a dead-time error; the sign is fixed by the model.
  if (!(*u >= 0.0 && *u <= 5.0)) {
    throw MotorDescriptionError(
        fmt::format("{}: key 'drive.voltage_error_V' must be within [0, 5] V, got {}",
                    Where(source, drive.get("voltage_error_V")->source()), *u));
  }
  m.voltage_error_V = *u;
  if (knee) {
    if (!(*knee >= 0.0 && *knee <= 100.0)) {
      throw MotorDescriptionError(
          fmt::format("{}: key 'drive.voltage_error_knee_A' must be within [0, 100] A, got {}",
                      Where(source, drive.get("voltage_error_knee_A")->source()), *knee));
    }
    m.voltage_error_knee_A = *knee;
  }
}

// The drive's current limit, |i_dq|. Far above any drive this gateway watches is a typo (a value
// in mA), and a silence's worst case would trip every pump at once.
void ParseMaxCurrent(const toml::table& drive, std::string_view source, MotorDescription& m) {
  const auto i = Number(drive, "max_current_A", "drive.max_current_A", source, false);
  if (!i) return;
  if (!(*i > 0.0 && *i <= 10000.0)) {
    throw MotorDescriptionError(
        fmt::format("{}: key 'drive.max_current_A' must be within (0, 10000] A, got {}",
                    Where(source, drive.get("max_current_A")->source()), *i));
  }
  m.max_current_A = *i;
}

}  // namespace

MotorDescription ParseMotorDescription(std::string_view text, std::string_view source) {
  toml::table root;
  try {
    root = toml::parse(text, std::string(source));
  } catch (const toml::parse_error& e) {
    throw MotorDescriptionError(fmt::format("{}:{}:{}: {}", source, e.source().begin.line,
                                            e.source().begin.column, e.description()));
  }
  RejectUnknownKeys(root,
                    {"name", "pole_pairs", "rated_speed_rpm", "flux_Wb", "inductance_H",
                     "resistance", "drive", "magnet"},
                    "", source);
  MotorDescription m;
  if (const toml::node* name = root.get("name")) {
    if (!name->is_string()) {
      throw MotorDescriptionError(
          fmt::format("{}: key 'name' must be a string", Where(source, name->source())));
    }
    m.name = *name->value<std::string>();
  }
  const toml::node* pp = root.get("pole_pairs");
  if (pp == nullptr) {
    throw MotorDescriptionError(fmt::format("{}:1: missing key 'pole_pairs'", source));
  }
  if (!pp->is_integer() || *pp->value<std::int64_t>() < 1 || *pp->value<std::int64_t>() > 1000) {
    throw MotorDescriptionError(
        fmt::format("{}: key 'pole_pairs' must be an integer >= 1", Where(source, pp->source())));
  }
  m.pole_pairs = static_cast<int>(*pp->value<std::int64_t>());
  m.rated_speed_rpm = *Number(root, "rated_speed_rpm", "rated_speed_rpm", source, true);
  RequirePositive(m.rated_speed_rpm, root, "rated_speed_rpm", "rated_speed_rpm", source);
  m.flux_Wb = *Number(root, "flux_Wb", "flux_Wb", source, true);
  RequirePositive(m.flux_Wb, root, "flux_Wb", "flux_Wb", source);
  m.inductance_H = *Number(root, "inductance_H", "inductance_H", source, true);
  RequirePositive(m.inductance_H, root, "inductance_H", "inductance_H", source);

  const toml::node* res_node = root.get("resistance");
  if (res_node == nullptr || !res_node->is_table()) {
    throw MotorDescriptionError(
        fmt::format("{}: missing table [resistance]",
                    res_node ? Where(source, res_node->source()) : std::string(source) + ":1"));
  }
  const toml::table& res = *res_node->as_table();
  RejectUnknownKeys(
      res, {"r0_ohm", "t0_degC", "alpha_per_K", "plausible_min_degC", "plausible_max_degC"},
      "resistance.", source);
  m.copper.r0_ohm = *Number(res, "r0_ohm", "resistance.r0_ohm", source, true);
  RequirePositive(m.copper.r0_ohm, res, "r0_ohm", "resistance.r0_ohm", source);
  m.copper.t0_degC = *Number(res, "t0_degC", "resistance.t0_degC", source, true);
  m.copper.alpha_per_K = *Number(res, "alpha_per_K", "resistance.alpha_per_K", source, true);
  RequirePositive(m.copper.alpha_per_K, res, "alpha_per_K", "resistance.alpha_per_K", source);
  // Winding conductors have 3.8e-3..6e-3 per K (copper 3.93e-3); a coefficient near zero would
  // turn eq. 3's division by alpha into a huge, noise-driven winding temperature.
  if (m.copper.alpha_per_K < 1e-4 || m.copper.alpha_per_K > 2e-2) {
    throw MotorDescriptionError(
        fmt::format("{}: key 'resistance.alpha_per_K' must be within [0.0001, 0.02] per K (copper "
                    "3.93e-3), got {}",
                    Where(source, res.get("alpha_per_K")->source()), m.copper.alpha_per_K));
  }
  if (auto v = Number(res, "plausible_min_degC", "resistance.plausible_min_degC", source, false)) {
    m.plausible_min_degC = *v;
  }
  if (auto v = Number(res, "plausible_max_degC", "resistance.plausible_max_degC", source, false)) {
    m.plausible_max_degC = *v;
  }
  if (!(m.plausible_min_degC < m.plausible_max_degC) || PlausibleMinResistance_ohm(m) <= 0.0 ||
      !(PlausibleMinResistance_ohm(m) < PlausibleMaxResistance_ohm(m))) {
    throw MotorDescriptionError(fmt::format(
        "{}:{}: keys 'resistance.plausible_min_degC' ({}) and 'resistance.plausible_max_degC' "
        "({}) must give a band of positive resistances",
        source, res.source().begin.line, m.plausible_min_degC, m.plausible_max_degC));
  }
  if (const toml::node* drive_node = root.get("drive")) {
    if (!drive_node->is_table()) {
      throw MotorDescriptionError(
          fmt::format("{}: key 'drive' must be a table", Where(source, drive_node->source())));
    }
    const toml::table& drive = *drive_node->as_table();
    RejectUnknownKeys(
        drive, {"max_current_A", "uq_resolution_V", "voltage_error_V", "voltage_error_knee_A"},
        "drive.", source);
    if (auto v = Number(drive, "uq_resolution_V", "drive.uq_resolution_V", source, false)) {
      // 12 bits over a 48 V link is 23 mV; a step of volts would be no voltage measurement.
      if (!(*v > 0.0 && *v <= 10.0)) {
        throw MotorDescriptionError(
            fmt::format("{}: key 'drive.uq_resolution_V' must be within (0, 10] V, got {}",
                        Where(source, drive.get("uq_resolution_V")->source()), *v));
      }
      m.uq_resolution_V = *v;
    }
    ParseVoltageError(drive, source, m);
    ParseMaxCurrent(drive, source, m);
  }
  if (const toml::node* magnet_node = root.get("magnet")) ParseMagnetLaw(*magnet_node, source, m);
  return m;
}

std::string_view MotorPresetText(std::string_view name) noexcept {
  if (name == "han2019-tmp") return kHan2019Tmp;
  return {};
}

std::vector<std::string> MotorPresetNames() { return {"han2019-tmp"}; }

MotorDescription MotorPreset(std::string_view name) {
  const std::string_view text = MotorPresetText(name);
  if (text.empty()) {
    throw MotorDescriptionError(
        fmt::format("unknown motor preset '{}' (known: han2019-tmp)", name));
  }
  return ParseMotorDescription(text, fmt::format("preset {}", name));
}

double ElectricalSpeed_rad_per_s(const MotorDescription& motor, double speed_rpm) noexcept {
  return speed_rpm * (2.0 * std::numbers::pi / 60.0) * motor.pole_pairs;
}

double MechanicalSpeed_rpm(const MotorDescription& motor, double w_rad_per_s) noexcept {
  return w_rad_per_s / (motor.pole_pairs * (2.0 * std::numbers::pi / 60.0));
}

double VoltageErrorQ_V(const MotorDescription& motor, double id_A, double iq_A) noexcept {
  const double mag = std::hypot(id_A, iq_A);
  if (!(motor.voltage_error_V > 0.0) || !(mag > 0.0)) return 0.0;
  const double shape =
      motor.voltage_error_knee_A > 0.0 ? std::tanh(mag / motor.voltage_error_knee_A) : 1.0;
  return motor.voltage_error_V * shape * iq_A / mag;
}

double PlausibleMinResistance_ohm(const MotorDescription& motor) noexcept {
  return ResistanceAt(motor.copper, motor.plausible_min_degC);
}

double PlausibleMaxResistance_ohm(const MotorDescription& motor) noexcept {
  return ResistanceAt(motor.copper, motor.plausible_max_degC);
}

}  // namespace pumptherm::estimators
