#pragma once
/// Input columns of `pumptherm simulate` and `pumptherm estimate`: the project's names
/// (`speed_rpm`, `id_A`, `iq_A`, `ambient_degC`, `coolant_degC`, `<node>_degC`; files read under
/// `_C` too, tools/common/csv.hpp), or those of a known data
/// set (`--columns paderborn`), and the initial temperatures (`--initial`).

#include <fmt/core.h>

#include <Eigen/Dense>
#include <cmath>
#include <string>

#include "estimators/thermal_model.hpp"
#include "tools/common/csv.hpp"
#include "tools/pumptherm/subcommand.hpp"

namespace pumptherm::tools {

/// The CSV column that holds `standard` (one of the project's names above) under `preset`:
/// "" keeps the project's names; "paderborn" reads the Paderborn data set (Kaggle "Electric
/// Motor Temperature", Kirchgaessner, Wallscheid, Boecker): motor_speed, i_d, i_q, ambient,
/// coolant, and node temperatures without the `_degC` suffix. Throws InputError for an unknown
/// preset.
inline std::string InputColumn(const std::string& preset, const std::string& standard) {
  if (preset.empty()) return standard;
  if (preset != "paderborn") {
    throw InputError(fmt::format("--columns: unknown preset '{}' (known: paderborn)", preset));
  }
  if (standard == "speed_rpm") return "motor_speed";
  if (standard == "id_A") return "i_d";
  if (standard == "iq_A") return "i_q";
  if (standard == "ambient_degC") return "ambient";
  if (standard == "coolant_degC") return "coolant";
  if (standard.ends_with("_degC")) return standard.substr(0, standard.size() - 5);
  return standard;
}

/// Initial state temperatures from `--initial` (`ambient`: every state at the first ambient
/// temperature; `first-row`: each state at its measured `<node>_degC` of the first row) unless
/// `initial_degC` (a number from `--initial-C`) is given. Throws InputError for another word,
/// and CsvError (naming row and column) when a first-row column is missing or not a number.
inline Eigen::VectorXd InitialTemperatures_degC(const estimators::ThermalModel& model,
                                                const CsvTable& csv, const std::string& preset,
                                                const std::string& initial, double initial_degC,
                                                double first_ambient_degC) {
  const int n = model.StateCount();
  if (std::isfinite(initial_degC)) return Eigen::VectorXd::Constant(n, initial_degC);
  if (initial == "ambient") return Eigen::VectorXd::Constant(n, first_ambient_degC);
  if (initial != "first-row") {
    throw InputError(fmt::format("--initial: '{}' is neither 'ambient' nor 'first-row'", initial));
  }
  Eigen::VectorXd x(n);
  for (int s = 0; s < n; ++s) {
    x(s) = csv.Column(
        InputColumn(preset, model.StateNames()[static_cast<std::size_t>(s)] + "_degC"))[0];
  }
  return x;
}

}  // namespace pumptherm::tools
