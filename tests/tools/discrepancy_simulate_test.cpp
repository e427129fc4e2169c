// The workflow's own simulation of every shipped model equals `pumptherm simulate` on the same
// data and start: within 0.1 K RMSE at the workflow's grid points. The Saheba and TMP models on
// data generated from themselves (cold start), wallscheid2017-4node on the real Paderborn
// profile 46 (warm start from the first row; its loss map and signed-current lookup are what
// averaging the inputs would lose). And on that real profile, a known missing effect (the
// model's speed-dependent convection stripped) is the best candidate on held-out data.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "estimators/thermal_model.hpp"
#include "tests/common/test_files.hpp"
#include "tests/common/test_temp_dir.hpp"
#include "tests/tools/discrepancy_cases.hpp"
#include "tools/discrepancy/workflow.hpp"

namespace pd = pumptherm::tools::discrepancy;
namespace pe = pumptherm::estimators;

namespace {

using pumptherm::test_files::ReadFile;
using pumptherm::test_files::SharedDir;

std::string SimulateDir() {
  return pumptherm::test_files::TestTempDir("pumptherm_discrepancy_simulate_test");
}

/// The model written to a file of its own with the tables it names by absolute path.
std::string ModelFile(const std::string& name) {
  std::string text = pumptherm::test_files::ReadModel(name);
  const std::string rel = "../../../../shared";
  const std::string shared = SharedDir();
  for (std::size_t p = text.find(rel); p != std::string::npos;
       p = text.find(rel, p + shared.size()))
    text.replace(p, rel.size(), shared);
  const std::string path = SimulateDir() + "/" + name + ".toml";
  std::ofstream(path) << text;
  return path;
}

/// How the tables a model file names are read (relative to the file).
pe::ThermalModelFiles FilesOf(const std::string& model_path) {
  return {std::filesystem::path(model_path).parent_path().string(),
          [](const std::string& p) { return ReadFile(p); }};
}

/// Paderborn profile 46 with its columns renamed to the workflow's.
std::string PaderbornCsv() {
  std::ifstream f(SharedDir() + "/data/paderborn/profile46_every10th_dt5s.csv");
  if (!f) return "";
  std::string header, rest;
  std::getline(f, header);
  std::stringstream ss;
  ss << f.rdbuf();
  std::string renamed;
  std::stringstream hs(header);
  for (std::string c; std::getline(hs, c, ',');) {
    static const std::map<std::string, std::string> kName{{"motor_speed", "speed_rpm"},
                                                          {"i_d", "id_A"},
                                                          {"i_q", "iq_A"},
                                                          {"ambient", "ambient_C"},
                                                          {"coolant", "coolant_C"},
                                                          {"pm", "pm_C"},
                                                          {"stator_yoke", "stator_yoke_C"},
                                                          {"stator_tooth", "stator_tooth_C"},
                                                          {"stator_winding", "stator_winding_C"}};
    const auto it = kName.find(c);
    renamed += (renamed.empty() ? "" : ",") + (it == kName.end() ? c : it->second);
  }
  const std::string path = SimulateDir() + "/profile46.csv";
  std::ofstream(path) << renamed << "\n" << ss.str();
  return path;
}

/// `pumptherm simulate` output: column name -> values.
std::map<std::string, std::vector<double>> Simulate(const std::string& model,
                                                    const std::string& csv,
                                                    const std::string& initial) {
  const std::string out = SimulateDir() + "/simulated.csv";
  const std::string cmd = std::string("'") + PUMPTHERM_CLI + "' simulate --model '" + model +
                          "' --input '" + csv + "' --initial " + initial + " --output '" + out +
                          "'";
  const int status = std::system(cmd.c_str());
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << cmd;
  std::map<std::string, std::vector<double>> cols;
  std::ifstream f(out);
  std::string line;
  std::getline(f, line);
  std::vector<std::string> names;
  std::stringstream hs(line);
  for (std::string c; std::getline(hs, c, ',');) names.push_back(c);
  while (std::getline(f, line)) {
    std::stringstream ls(line);
    std::size_t i = 0;
    for (std::string c; std::getline(ls, c, ',') && i < names.size(); ++i)
      cols[names[i]].push_back(std::stod(c));
  }
  return cols;
}

/// RMSE of the workflow's simulation against `simulate` at the grid points after the start.
double Compare(const std::string& model_path, const std::string& csv, const std::string& initial,
               const pd::Options& o = {}) {
  const pe::ThermalModel model =
      pe::ThermalModel::Parse(ReadFile(model_path), model_path, FilesOf(model_path));
  const pd::Data data = pd::ReadData(csv, model);
  const pd::Simulated w = pd::SimulateModel(model, data, o);
  const auto s = Simulate(model_path, csv, initial);
  const std::vector<double>& t = s.at("time_s");
  double ss = 0.0, hottest = -INFINITY;
  std::size_t n = 0, row = 0;
  for (std::size_t j = 1; j < w.time_s.size(); ++j) {
    while (row < t.size() && t[row] < w.time_s[j] - 1e-9) ++row;
    EXPECT_LT(row, t.size());
    if (row >= t.size()) break;
    for (std::size_t i = 0; i < w.nodes.size(); ++i, ++n) {
      const double e = w.temps_degC[i][j] - s.at(w.nodes[i] + "_degC")[row];
      hottest = std::max(hottest, w.temps_degC[i][j]);
      ss += e * e;
    }
  }
  const double rmse = n ? std::sqrt(ss / static_cast<double>(n)) : INFINITY;
  EXPECT_LT(hottest, 250.0) << "the data drive " << model_path << " out of any physical range";
  std::printf(
      "%s on %s: workflow vs simulate RMSE %.2e K over %zu values (%s), hottest %.1f degC\n",
      model_path.c_str(), csv.c_str(), rmse, n, w.averaged ? "inputs averaged" : "row by row",
      hottest);
  return rmse;
}

/// Two hours at 10 s generated from the model itself; measured: every state of the model.
std::string GeneratedCsv(const std::string& name) {
  const pe::ThermalModel model =
      pe::ThermalModel::Parse(pumptherm::test_files::ReadModel(name), name);
  pd::HiddenDataConfig c;
  c.model_text = pumptherm::test_files::ReadModel(name);
  c.model_source = name;
  c.duration_s = 2.0 * 3600.0;
  c.step_s = 10.0;
  c.measured_nodes = model.StateNames();
  if (name == "tmp-generic") {  // its motor's range (han2019-tmp): 21000 r/min, a few amperes
    c.max_speed_rpm = 21000.0;
    c.max_current_A = 4.5;
  }
  const std::string path = SimulateDir() + "/" + name + ".csv";
  pd::WriteData(path, pd::MakeHiddenEffectData(c), model.UsesCoolant());
  return path;
}

}  // namespace

TEST(DiscrepancySimulate, SahebaAndTmpModelsEqualSimulate) {
  for (const char* name : {"saheba2010-baseline", "saheba2010-improved", "tmp-generic"})
    EXPECT_LT(Compare(ModelFile(name), GeneratedCsv(name), "ambient"), 0.1) << name;
}

TEST(DiscrepancySimulate, WallscheidOnPaderbornEqualsSimulate) {
  const std::string csv = PaderbornCsv();
  if (csv.empty() || !std::ifstream(SharedDir() + "/reference/wallscheid-losses/total_loss_W.csv"))
    GTEST_SKIP() << "Paderborn data or the Wallscheid loss map absent from " << SharedDir()
                 << " (set PUMPTHERM_SHARED_DIR)";
  EXPECT_LT(Compare(ModelFile("wallscheid2017-4node"), csv, "first-row"), 0.1);
}

// Data longer than max_exact_rows are simulated with inputs averaged over grid steps: the run
// says so, and the cost it reports is the averaged simulation's RMSE against `simulate`.
TEST(DiscrepancySimulate, AveragedInputsReportTheirCost) {
  const std::string csv = PaderbornCsv();
  if (csv.empty() || !std::ifstream(SharedDir() + "/reference/wallscheid-losses/total_loss_W.csv"))
    GTEST_SKIP() << "Paderborn data or the Wallscheid loss map absent";
  pd::Options o;
  o.max_exact_rows = 10;
  o.min_grid_step_s = 20.0;
  o.effects = {"sensor_offset"};  // sensor effects need no new simulation: a cheap run
  o.max_effects = 1;
  const double vs_simulate_K = Compare(ModelFile("wallscheid2017-4node"), csv, "first-row", o);
  const std::string path = ModelFile("wallscheid2017-4node");
  const pe::ThermalModel model = pe::ThermalModel::Parse(ReadFile(path), path, FilesOf(path));
  const pd::Data data = pd::ReadData(csv, model);
  const pd::Result r = pd::Run(ReadFile(path), path, data, data, o, FilesOf(path));
  EXPECT_EQ(r.simulation, "averaged");
  EXPECT_GT(vs_simulate_K, 0.01);  // the loss map is nonlinear in the current: not exact
  EXPECT_NEAR(r.averaging_cost_train_K, vs_simulate_K, 1e-9);
  EXPECT_NEAR(r.averaging_cost_validate_K, vs_simulate_K, 1e-9);
}

namespace {

/// Writes rows [from, to) of the CSV at `path` (after its header) to `out`.
std::string Rows(const std::string& path, std::size_t from, std::size_t to,
                 const std::string& out) {
  std::ifstream f(path);
  std::ofstream o(SimulateDir() + "/" + out);
  std::string line;
  std::getline(f, line);
  o << line << "\n";
  for (std::size_t k = 0; std::getline(f, line); ++k)
    if (k >= from && k < to) o << line << "\n";
  return SimulateDir() + "/" + out;
}

/// The model with every speed_norm in an edge resistance set to 0 (its standstill values).
std::string StrippedModelFile() {
  std::ifstream f(ModelFile("wallscheid2017-4node"));
  std::string text, line;
  while (std::getline(f, line)) {
    if (line.rfind("resistance_K_per_W", 0) == 0)
      for (std::size_t p = line.find("speed_norm"); p != std::string::npos;
           p = line.find("speed_norm", p))
        line.replace(p, 10, "0");
    text += line + "\n";
  }
  const std::string path = SimulateDir() + "/w4-nospeed.toml";
  std::ofstream(path) << text;
  return path;
}

}  // namespace

// Real data with a known missing effect: the Wallscheid model without its speed-dependent
// convection, fitted on one half of Paderborn profile 46 and scored on the other, both ways.
// The best candidate must be speed_dependent_cooling (on the model's cooling path), with a
// significant gain that agrees between the halves, cutting the held-out RMSE by at least 30 %.
TEST(DiscrepancyRealData, StrippedSpeedDependenceIsTheBestCandidateBothWays) {
  const std::string csv = PaderbornCsv();
  if (csv.empty() || !std::ifstream(SharedDir() + "/reference/wallscheid-losses/total_loss_W.csv"))
    GTEST_SKIP() << "Paderborn data or the Wallscheid loss map absent";
  const std::string a = Rows(csv, 0, 109, "a.csv"), b = Rows(csv, 109, 1000, "b.csv");
  const std::string path = StrippedModelFile();
  const pe::ThermalModel model = pe::ThermalModel::Parse(ReadFile(path), path, FilesOf(path));
  const pd::Data da = pd::ReadData(a, model), db = pd::ReadData(b, model);
  pd::Options o;
  o.max_effects = 1;
  std::vector<double> gains;
  for (const auto& [train, validate] : {std::pair{&da, &db}, std::pair{&db, &da}}) {
    const pd::Result r = pd::Run(ReadFile(path), path, *train, *validate, o, FilesOf(path));
    ASSERT_FALSE(r.rounds.empty());
    const pd::Candidate& best = r.rounds.front().candidates.front();
    std::printf("fit on %s: %s, best %s validate %.3f -> %.3f K, dIC %.1f, g %.3f (%.3f to %.3f)\n",
                train->source.c_str(), r.verdict.c_str(), best.label.c_str(),
                r.rounds.front().base_validate_rmse_K, best.validate_rmse_K, best.delta_ic,
                best.parameters[0].value, best.parameters[0].low95, best.parameters[0].high95);
    EXPECT_EQ(best.effect, "speed_dependent_cooling");
    EXPECT_TRUE(best.eligible);
    EXPECT_LT(best.validate_rmse_K, 0.7 * r.rounds.front().base_validate_rmse_K);
    gains.push_back(best.parameters[0].value);
    EXPECT_NE(r.verdict, "none");
  }
  ASSERT_EQ(gains.size(), 2u);
  EXPECT_NEAR(gains[0], gains[1], 0.5 * std::max(gains[0], gains[1]));
}
