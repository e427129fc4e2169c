// pumptherm simulate: the thermal network alone over a recorded or made-up load profile.
#include <fmt/core.h>

#include <cmath>

#include "estimators/thermal_discretisation.hpp"
#include "tools/common/csv.hpp"
#include "tools/pumptherm/model_files.hpp"
#include "tools/pumptherm/subcommand.hpp"

namespace pumptherm::tools {
namespace {

struct SimulateOptions {
  std::string model;
  std::string input;
  std::string output = "-";
  double initial_degC = std::nan("");
};

int RunSimulate(const SimulateOptions& o) {
  const estimators::ThermalModel model = LoadThermalModel(o.model);
  std::vector<double> t, speed, id, iq, amb, cool;
  try {
    const CsvTable csv = CsvTable::Read(o.input);
    t = csv.Time();
    speed = csv.Column("speed_rpm");
    id = csv.Column("id_A");
    iq = csv.Column("iq_A");
    amb = csv.Column("ambient_C");
    cool = model.UsesCoolant() ? csv.Column("coolant_C") : amb;
  } catch (const CsvError& e) {
    throw InputError(e.what());
  }
  if (t.empty()) throw InputError(fmt::format("{}: no data rows", o.input));
  auto inputs = [&](std::size_t k) {
    estimators::ThermalInputs in;
    in.speed_rpm = speed[k];
    in.id_A = id[k];
    in.iq_A = iq[k];
    in.ambient_degC = amb[k];
    in.coolant_degC = cool[k];
    return in;
  };
  const int n = model.StateCount();
  Eigen::VectorXd x = Eigen::VectorXd::Constant(n, std::isnan(o.initial_degC) ? amb[0] : o.initial_degC);
  std::vector<std::string> columns{"time_s"};
  for (const auto& node : model.Nodes()) columns.push_back(node.name + "_C");
  CsvWriter out(o.output, columns);
  std::vector<double> row(columns.size());
  estimators::ThermalLinearModel lin;
  estimators::ThermalDiscretiser disc(1e-4);
  Eigen::VectorXd next(n);
  for (std::size_t k = 0; k < t.size(); ++k) {
    if (k > 0) {
      model.Linearise(inputs(k - 1), lin);
      disc.Update(lin, t[k] - t[k - 1]);
      disc.Propagate(x, lin, next);
      x = next;
    }
    const Eigen::VectorXd all = model.AllTemperatures_degC(inputs(k), x);
    row[0] = t[k];
    for (Eigen::Index i = 0; i < all.size(); ++i) row[static_cast<std::size_t>(i) + 1] = all(i);
    out.Row(row);
  }
  out.Close();
  return 0;
}

const SubcommandRegistrar kRegistrar{
    "simulate", "Run a thermal network model over a load profile (no measurements)",
    [](CLI::App& app) -> std::function<int()> {
      auto o = std::make_shared<SimulateOptions>();
      app.add_option("--model,-m", o->model, "Shipped model name or path to a model .toml")->required();
      app.add_option("--input,-i", o->input,
                     "CSV with time_s, speed_rpm, id_A, iq_A, ambient_C (and coolant_C if the model "
                     "has a coolant); '-' = stdin")
          ->required();
      app.add_option("--output,-o", o->output, "CSV to write: time_s and <node>_C per node ('-' = stdout)");
      app.add_option("--initial-C", o->initial_degC,
                     "Initial temperature of every node, degC (default: the first ambient_C)");
      app.footer(
          "Inputs are held over each interval (zero-order hold, exact discretisation).\n"
          "Example:\n  pumptherm simulate --model saheba2010-improved --input profile.csv "
          "--output temps.csv");
      return [o] { return RunSimulate(*o); };
    }};

}  // namespace
}  // namespace pumptherm::tools
