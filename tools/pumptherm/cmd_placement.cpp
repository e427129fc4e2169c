// pumptherm placement: mean-square estimation error for every candidate sensor node
// (Saheba 2010 eqs. 35-37, Tables 5 and 6).
#include <fmt/core.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>

#include "estimators/placement.hpp"
#include "estimators/thermal_discretisation.hpp"
#include "tools/pumptherm/model_files.hpp"
#include "tools/pumptherm/subcommand.hpp"

namespace pumptherm::tools {
namespace {

struct PlacementOptions {
  std::string model;
  double speed_rpm = 800.0;
  std::vector<double> currents_A{40.0, 52.5, 65.0};
  double ambient_degC = 25.0;
  double coolant_degC = 25.0;
  double scale_current_A = 50.0;
  double scale_duration_s = 2700.0;
  estimators::PlacementConfig config;
  // Whether the command line gave these; if not, the model's [operating_range] does.
  bool speed_given = false;
  bool currents_given = false;
  bool scale_given = false;
};

/// The model's typical operation replaces the defaults the command line did not override.
void ApplyOperatingRange(const estimators::ThermalModel& model, PlacementOptions& o) {
  const estimators::ThermalOperatingRange* r = model.OperatingRange();
  if (!r) return;
  if (!o.speed_given) o.speed_rpm = r->speed_rpm;
  if (!o.currents_given) o.currents_A = r->iq_A;
  if (!o.scale_given) o.scale_current_A = r->scale_current_A;
}

int RunPlacement(PlacementOptions& o) {
  const estimators::ThermalModel model = LoadThermalModel(o.model);
  ApplyOperatingRange(model, o);
  if (o.currents_A.empty()) throw InputError("--currents-A: give at least one current");
  for (double i : o.currents_A) {
    estimators::ThermalInputs in;
    in.speed_rpm = o.speed_rpm;
    in.iq_A = i;
    in.ambient_degC = o.ambient_degC;
    in.coolant_degC = o.coolant_degC;
    o.config.operating_points.push_back(in);
  }
  // Nondimensional states: the temperature rises at the end of a constant-current run from
  // ambient (the paper uses the final values of its 50 A, 2700 s run, Fig. 4).
  estimators::ThermalInputs in;
  in.speed_rpm = o.speed_rpm;
  in.iq_A = o.scale_current_A;
  in.ambient_degC = o.ambient_degC;
  in.coolant_degC = o.coolant_degC;
  estimators::ThermalLinearModel lin;
  model.Linearise(in, lin);
  estimators::ThermalDiscreteModel d;
  estimators::DiscretiseZoh(lin.a_per_s, o.scale_duration_s, d);
  const Eigen::VectorXd x0 = Eigen::VectorXd::Constant(model.StateCount(), o.ambient_degC);
  const Eigen::VectorXd xf = d.ad * x0 + d.phi_s * lin.f_K_per_s;
  o.config.scale_K = xf - x0;
  if ((o.config.scale_K.array().abs() < 1e-6).any()) {
    throw InputError("the scaling run leaves a node at ambient; raise --scale-current-A");
  }
  const auto rows = estimators::SensorPlacement(model, o.config);
  auto rank = [&](auto key) {
    std::vector<std::size_t> idx(rows.size());
    for (std::size_t i = 0; i < idx.size(); ++i) idx[i] = i;
    std::stable_sort(idx.begin(), idx.end(),
                     [&](auto a, auto b) { return key(rows[a]) < key(rows[b]); });
    std::vector<std::size_t> r(rows.size());
    for (std::size_t i = 0; i < idx.size(); ++i) r[idx[i]] = i + 1;
    return r;
  };
  const auto rank_all = rank([](const auto& r) { return r.mse_all; });
  const auto rank_w = rank([](const auto& r) { return r.mse_windings; });
  fmt::print("# operating points {}\n",
             model.OperatingRange()
                 ? "from the model's [operating_range] where not given"
                 : "from the command line's defaults (the model has no [operating_range])");
  fmt::print("# model {}; {} r/min; A_D at {} A, each over 1/3 of N = {} steps of {} s\n",
             model.Name(), o.speed_rpm, fmt::join(o.currents_A, ", "), o.config.steps,
             o.config.dt_s);
  fmt::print(
      "# nondimensional by the rises after {} s at {} A; Sm^1/2 {} K, Sp^1/2 {} K, S0^1/2 {} K\n",
      o.scale_duration_s, o.scale_current_A, o.config.measurement_sd_K, o.config.process_sd_K,
      o.config.initial_sd_K);
  fmt::print("{:<16} {:>14} {:>5} {:>16} {:>5}\n", "sensor_node", "mse_all", "rank", "mse_windings",
             "rank");
  for (std::size_t i = 0; i < rows.size(); ++i) {
    fmt::print("{:<16} {:>14.6g} {:>5} {:>16.6g} {:>5}\n", rows[i].node, rows[i].mse_all,
               rank_all[i], rows[i].mse_windings, rank_w[i]);
  }
  return 0;
}

const SubcommandRegistrar kPlacementRegistrar{
    "placement", "Kalman-filter mean-square error for each candidate sensor node",
    [](CLI::App& app) -> std::function<int()> {
      auto o = std::make_shared<PlacementOptions>();
      app.add_option("--model,-m", o->model, "Shipped model name or path to a model .toml")
          ->required();
      app.add_option(
             "--speed-rpm", o->speed_rpm,
             "Speed of the operating points (default: the model's [operating_range], else this)")
          ->capture_default_str()
          ->each([o](const std::string&) { o->speed_given = true; });
      app.add_option("--currents-A", o->currents_A,
                     "q-axis currents whose A_D each hold for a third of the window (min mid max; "
                     "default: the model's [operating_range], else these)")
          ->delimiter(',')
          ->capture_default_str()
          ->each([o](const std::string&) { o->currents_given = true; });
      app.add_option("--ambient-C", o->ambient_degC, "Ambient temperature")->capture_default_str();
      app.add_option("--coolant-C", o->coolant_degC, "Coolant temperature")->capture_default_str();
      app.add_option("--dt-s", o->config.dt_s, "Sampling time tau")->capture_default_str();
      app.add_option("--steps", o->config.steps, "Window length N")->capture_default_str();
      app.add_option("--measurement-sd-K", o->config.measurement_sd_K, "eq. 38")
          ->capture_default_str();
      app.add_option("--process-sd-K", o->config.process_sd_K, "eq. 39, per step")
          ->capture_default_str();
      app.add_option("--initial-sd-K", o->config.initial_sd_K, "S(0)^1/2 per state")
          ->capture_default_str();
      app.add_option(
             "--scale-current-A", o->scale_current_A,
             "Current of the scaling run (default: the model's [operating_range], else this)")
          ->capture_default_str()
          ->each([o](const std::string&) { o->scale_given = true; });
      app.add_option("--scale-duration-s", o->scale_duration_s, "Length of the scaling run")
          ->capture_default_str();
      app.footer("Example:\n  pumptherm placement --model saheba2010-improved");
      return [o] { return RunPlacement(*o); };
    }};

}  // namespace
}  // namespace pumptherm::tools
