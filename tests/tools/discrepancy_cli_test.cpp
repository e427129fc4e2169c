// `pumptherm discrepancy` end to end: outputs with the fields, a model.toml that loads,
// and bad CSV input as exit code 2 naming row and column.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "estimators/thermal_model.hpp"
#include "tests/tools/discrepancy_cases.hpp"

namespace pd = pumptherm::tools::discrepancy;

namespace {

std::string Dir() {
  const auto d = std::filesystem::temp_directory_path() / "pumptherm_discrepancy_cli_test";
  std::filesystem::create_directories(d);
  return d.string();
}

std::string Slurp(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

struct CliRun {
  int exit_code;
  std::string err;
};

CliRun Discrepancy(const std::string& args) {
  const std::string err = Dir() + "/err.txt";
  const std::string cmd = std::string("'") + PUMPTHERM_CLI + "' discrepancy " + args + " 2> '" + err + "'";
  const int status = std::system(cmd.c_str());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, Slurp(err)};
}

}  // namespace

TEST(DiscrepancyCli, WritesReportModelAndHtml) {
  auto [train, validate] =
      pumptherm::tests::HiddenCase("saheba2010-baseline", {{"iron_loss_scale", {2.0}, {}}}, 4.0, 60.0);
  pd::WriteData(Dir() + "/train.csv", train, false);
  pd::WriteData(Dir() + "/validate.csv", validate, false);
  const CliRun r = Discrepancy("--model saheba2010-baseline --train " + Dir() + "/train.csv --validate " +
                            Dir() + "/validate.csv --out " + Dir() + "/out --max-effects 1 " +
                            "--effects iron_loss_scale,rotor_loss,frame_thermal_mass");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string json = Slurp(Dir() + "/out/report.json");
  for (const char* key : {"\"verdict\": \"named\"", "\"effect\": \"iron_loss_scale\"", "\"effects\"",
                          "\"candidates\"", "\"gap\"", "\"rmse_K\"", "\"max_abs_K\"", "\"ci95\"",
                          "\"reading\"", "\"validate\"", "\"train\""})
    EXPECT_NE(json.find(key), std::string::npos) << key << "\n" << json;
  const std::string model = Slurp(Dir() + "/out/model.toml");
  EXPECT_NO_THROW(pumptherm::estimators::ThermalModel::Parse(model, "model.toml")) << model;
  EXPECT_NE(model.find("iron_loss_scale = "), std::string::npos);
  EXPECT_NE(Slurp(Dir() + "/out/report.html").find("<svg"), std::string::npos);
}

TEST(DiscrepancyCli, BadCellIsExit2NamingRowAndColumn) {
  std::ofstream(Dir() + "/bad.csv") << "time_s,speed_rpm,id_A,iq_A,ambient_C,frame_C\n"
                                       "0,800,0,40,22,22\n10,800,0,40,22,22.1\n20,800,0,forty,22,22.2\n";
  const CliRun r = Discrepancy("--model saheba2010-baseline --train " + Dir() + "/bad.csv --validate " +
                            Dir() + "/bad.csv --out " + Dir() + "/bad");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("iq_A"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("4"), std::string::npos) << r.err;  // file line 4
}

TEST(DiscrepancyCli, UnknownEffectIsExit2) {
  const CliRun r = Discrepancy("--model saheba2010-baseline --train x.csv --validate x.csv --out " + Dir() +
                            "/u --effects no_such_effect");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("no_such_effect"), std::string::npos) << r.err;
}
