// pumptherm simulate: the thermal network alone over a recorded or made-up load profile.
#include <fmt/core.h>

#include <algorithm>
#include <cmath>

#include "estimators/thermal_discretisation.hpp"
#include "tools/common/csv.hpp"
#include "tools/common/thermal_input_series.hpp"
#include "tools/pumptherm/model_files.hpp"
#include "tools/pumptherm/subcommand.hpp"
#include "tools/pumptherm/thermal_columns.hpp"

namespace pumptherm::tools {
namespace {

struct SimulateOptions {
  std::string model;
  std::string input;
  std::string output = "-";
  double initial_degC = std::nan("");
  std::string initial = "ambient";
  std::string columns;      ///< column preset ("" or "paderborn")
  double max_step_s = 0.0;  ///< 0: one step per row
  std::string interpolation = "hold";
};

int RunSimulate(const SimulateOptions& o) {
  const estimators::ThermalModel model = LoadThermalModel(o.model);
  if (o.interpolation != "hold" && o.interpolation != "linear") {
    throw InputError(fmt::format("--inputs: '{}' is neither 'hold' nor 'linear'", o.interpolation));
  }
  if (!(o.max_step_s >= 0.0) || !std::isfinite(o.max_step_s)) {
    throw InputError("--max-step-s: must be a finite number >= 0");
  }
  ThermalInputSeries series;
  Eigen::VectorXd x;
  try {
    const CsvTable csv = CsvTable::Read(o.input);
    series = ReadThermalInputs(
        csv, {[&](const std::string& standard) { return InputColumn(o.columns, standard); },
              model.UsesCoolant()});
    if (series.size() > 0) {
      x = InitialTemperatures_degC(model, csv, o.columns, o.initial, o.initial_degC,
                                   series.ambient_degC[0]);
    }
  } catch (const CsvError& e) {
    throw InputError(e.what());
  }
  const std::vector<double>& t = series.time_s;
  if (t.empty()) throw InputError(fmt::format("{}: no data rows", o.input));
  // Between rows: the earlier row's inputs held, or interpolated linearly.
  const bool linear = o.interpolation == "linear";
  const int n = model.StateCount();
  std::vector<std::string> columns{"time_s"};
  for (const auto& node : model.Nodes()) columns.push_back(node.name + "_degC");
  CsvWriter out(o.output, columns);
  std::vector<double> row(columns.size());
  estimators::ThermalLinearModel lin;
  estimators::ThermalDiscretiser disc(1e-4);
  Eigen::VectorXd next(n);
  for (std::size_t k = 0; k < t.size(); ++k) {
    if (k > 0) {
      const double dt_s = t[k] - t[k - 1];
      const int steps = o.max_step_s > 0.0
                            ? std::max(1, static_cast<int>(std::ceil(dt_s / o.max_step_s - 1e-9)))
                            : 1;
      for (int j = 0; j < steps; ++j) {
        model.Linearise(series.Between(k, static_cast<double>(j) / steps, linear), x, lin);
        disc.Update(lin, dt_s / steps);
        disc.Propagate(x, lin, next);
        x = next;
      }
    }
    const Eigen::VectorXd all = model.AllTemperatures_degC(series.Inputs(k), x);
    row[0] = t[k];
    for (Eigen::Index i = 0; i < all.size(); ++i) row[static_cast<std::size_t>(i) + 1] = all(i);
    out.Row(row);
  }
  out.Close();
  return 0;
}

const SubcommandRegistrar kSimulateRegistrar{
    "simulate", "Run a thermal network model over a load profile (no measurements)",
    [](CLI::App& app) -> std::function<int()> {
      auto o = std::make_shared<SimulateOptions>();
      app.add_option("--model,-m", o->model, "Shipped model name or path to a model .toml")
          ->required();
      app.add_option(
             "--input,-i", o->input,
             "CSV with time_s, speed_rpm, id_A, iq_A, ambient_degC (and coolant_degC if the model "
             "has a coolant); '-' = stdin")
          ->required();
      app.add_option("--output,-o", o->output,
                     "CSV to write: time_s and <node>_degC per node ('-' = stdout)");
      app.add_option("--initial-C", o->initial_degC,
                     "Initial temperature of every node, degC (overrides --initial)");
      app.add_option("--initial", o->initial,
                     "Initial temperatures: 'ambient' (every node at the first ambient_degC) or "
                     "'first-row' (each node at its <node>_degC of the first row)")
          ->capture_default_str();
      app.add_option(
          "--columns", o->columns,
          "Column names of a known data set: 'paderborn' (motor_speed, i_d, i_q, ambient, "
          "coolant, <node>)");
      app.add_option(
             "--max-step-s", o->max_step_s,
             "Longest integration step, s; rows further apart are split (0 = one step per row)")
          ->capture_default_str();
      app.add_option("--inputs", o->interpolation,
                     "Inputs between rows: 'hold' (the earlier row's) or 'linear' (interpolated at "
                     "the start of each step)")
          ->capture_default_str();
      app.footer(
          "Each step is discretised exactly (zero-order hold) with its inputs held over it.\n"
          "Examples:\n  pumptherm simulate --model saheba2010-improved --input profile.csv "
          "--output temps.csv\n"
          "  pumptherm simulate --model tests/data/models/wallscheid2017-4node.toml --columns "
          "paderborn --initial first-row "
          "--input profile46.csv");
      return [o] { return RunSimulate(*o); };
    }};

}  // namespace
}  // namespace pumptherm::tools
