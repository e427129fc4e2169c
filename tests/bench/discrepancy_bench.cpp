// Benchmark of the discrepancy workflow ("Figures"): 24 hours of data at 1 Hz with five
// measured nodes, train and validate each, the whole run timed from reading the CSV files to
// writing report.json, model.toml and report.html. Prints the figure as JSON; never fails on time.
//
//   build/tests/bench/discrepancy_bench [--hours 24] [--step-s 1] [--max-exact-rows 20000]
#include <fmt/core.h>

#include <chrono>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "estimators/thermal_model.hpp"
#include "tests/common/test_files.hpp"
#include "tools/discrepancy/data.hpp"
#include "tools/discrepancy/hidden_data.hpp"
#include "tools/discrepancy/report.hpp"
#include "tools/discrepancy/workflow.hpp"

namespace pd = pumptherm::tools::discrepancy;

int main(int argc, char** argv) {
  double hours = 24.0, step_s = 1.0;
  pd::Options options;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string a = argv[i];
    if (a == "--hours") hours = std::atof(argv[i + 1]);
    if (a == "--step-s") step_s = std::atof(argv[i + 1]);
    if (a == "--max-exact-rows") options.max_exact_rows = std::atol(argv[i + 1]);
  }
  const std::string model_path = pumptherm::test_files::ModelPath("saheba2010-baseline");
  const std::string text = pumptherm::test_files::ReadFile(model_path);
  // The paper's case: data from saheba2010-improved, the baseline model to correct.
  pd::HiddenDataConfig c;
  c.model_text = pumptherm::test_files::ReadModel("saheba2010-improved");
  c.model_source = "saheba2010-improved";
  c.duration_s = hours * 3600.0;
  c.step_s = step_s;
  const auto dir = std::filesystem::temp_directory_path() / "pumptherm_discrepancy_bench";
  std::filesystem::create_directories(dir);
  const std::string train_csv = (dir / "train.csv").string(),
                    val_csv = (dir / "validate.csv").string();
  pd::WriteData(train_csv, pd::MakeHiddenEffectData(c), false);
  c.profile_seed = 2;
  c.noise_seed = 8;
  pd::WriteData(val_csv, pd::MakeHiddenEffectData(c), false);

  const auto t0 = std::chrono::steady_clock::now();
  const std::clock_t c0 = std::clock();
  const auto model = pumptherm::estimators::ThermalModel::Parse(text, model_path);
  const pd::Data train = pd::ReadData(train_csv, model);
  const pd::Data validate = pd::ReadData(val_csv, model);
  const pd::Result r = pd::Run(text, model_path, train, validate, options);
  pd::WriteReport((dir / "out").string(), r, "saheba2010-baseline", train_csv, val_csv);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const double cpu_s = static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC;
  std::string named;
  for (const auto& e : r.effects) named += (named.empty() ? "" : ",") + e.effect.name;
  fmt::print(
      "{{\"benchmark\": \"discrepancy_whole_run\", \"hours\": {}, \"step_s\": {}, "
      "\"rows_per_file\": {}, "
      "\"measured_nodes\": {}, \"run_time_s\": {:.2f}, \"cpu_time_s\": {:.2f}, \"verdict\": "
      "\"{}\", \"effects\": \"{}\", "
      "\"validate_max_abs_K\": [{:.3f}, {:.3f}], \"simulation\": \"{}\", \"averaging_cost_K\": "
      "[{:.4f}, {:.4f}], "
      "\"goal_s\": 60}}\n",
      hours, step_s, train.size(), train.measured.size(), s, cpu_s, r.verdict, named,
      r.validate_before.back().max_abs_K, r.validate_after.back().max_abs_K, r.simulation,
      r.averaging_cost_train_K, r.averaging_cost_validate_K);
  std::filesystem::remove_all(dir);
  return 0;
}
