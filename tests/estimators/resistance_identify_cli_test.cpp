// `pumptherm identify` run as a process: bad input gives exit code 2 and a message naming the
// row and column (or line and key); good input gives the documented output columns.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>

#include "estimators/motor.hpp"
#include "tests/common/run_command.hpp"
#include "tests/common/test_files.hpp"
#include "tools/common/csv.hpp"
#include "tools/sim/tmp_drive.hpp"

namespace pumptherm {
namespace {

using pumptherm::test_files::ReadFile;

std::string TempPath(const std::string& name) {
  return ::testing::TempDir() + "pumptherm_identify_" + name;
}

void WriteText(const std::string& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
}

struct Result {
  int exit_code;
  std::string err;
};

Result Identify(const std::string& name, const std::string& extra = "") {
  const std::string cmd = std::string("'") + PUMPTHERM_CLI + "' identify --input '" +
                          TempPath(name + ".csv") + "' --output '" + TempPath(name + ".out.csv") +
                          "' " + extra;
  auto r = pumptherm::test_files::RunCommandStderr(cmd, TempPath(name + ".err"));
  return {r.exit_code, std::move(r.out)};
}

constexpr const char* kHeader = "time_s,id_A,iq_A,ud_V,uq_V,speed_rpm\n";
constexpr const char* kRow1 = "0.00,0.0,2.0,-1.0,40.6,21000\n";
constexpr const char* kRow2 = "0.01,0.0,2.0,-1.0,40.6,21000\n";

TEST(IdentifyCli, MissingColumnIsExit2NamingColumn) {
  WriteText(TempPath("missing.csv"), "time_s,id_A,iq_A,ud_V,speed_rpm\n0,0,2,-1,21000\n");
  const Result r = Identify("missing");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("missing column 'uq_V'"), std::string::npos) << r.err;
}

TEST(IdentifyCli, NonNumericCellIsExit2NamingRowAndColumn) {
  WriteText(TempPath("text.csv"), std::string(kHeader) + kRow1 + "0.01,0.0,two,-1.0,40.6,21000\n");
  const Result r = Identify("text");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("row 3, column 'iq_A'"), std::string::npos) << r.err;
}

TEST(IdentifyCli, TimeGoingBackwardsIsExit2NamingRowAndColumn) {
  WriteText(TempPath("backwards.csv"), std::string(kHeader) + kRow1 + kRow2 + kRow1);
  const Result r = Identify("backwards");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("row 4, column 'time_s'"), std::string::npos) << r.err;
}

TEST(IdentifyCli, NaNIsExit2NamingRowAndColumn) {
  WriteText(TempPath("nan.csv"), std::string(kHeader) + kRow1 + "0.01,0.0,2.0,-1.0,nan,21000\n");
  const Result r = Identify("nan");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("row 3, column 'uq_V'"), std::string::npos) << r.err;
}

TEST(IdentifyCli, BadMotorFileIsExit2NamingLineAndKey) {
  WriteText(TempPath("motor.csv"), std::string(kHeader) + kRow1 + kRow2);
  std::string motor(estimators::MotorPresetText("han2019-tmp"));
  motor.replace(motor.find("flux_Wb = 0.0182"), 16, "flux_Wb = \"x\"");
  WriteText(TempPath("motor.toml"), motor);
  const Result r = Identify("motor", "--motor '" + TempPath("motor.toml") + "'");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("motor.toml:7: key 'flux_Wb'"), std::string::npos) << r.err;
  const Result unknown = Identify("motor", "--motor no-such-preset-or-file");
  EXPECT_EQ(unknown.exit_code, 2) << unknown.err;
}

// Ten simulated minutes (1-minute ramp, gas-load steps), columns in a shuffled order.
TEST(IdentifyCli, IdentifiesSimulatedTelemetry) {
  const estimators::MotorDescription motor = estimators::MotorPreset("han2019-tmp");
  sim::TmpDriveConfig cfg;
  cfg.motor = motor;
  cfg.ramp_s = 60.0;
  cfg.duration_s = 600.0;
  cfg.load_steps = true;
  cfg.load_step_mean_interval_s = 45.0;
  cfg.winding_degC = [](double) { return 45.0; };
  cfg.seed = 3;
  sim::TmpDrive plant(cfg);
  double true_r = 0.0;
  {
    tools::CsvWriter w(TempPath("good.csv"),
                       {"speed_rpm", "uq_V", "time_s", "iq_A", "ud_V", "id_A"});
    while (plant.Running()) {
      const sim::TmpDriveSample s = plant.Step();
      w.Row({s.speed_rpm, s.uq_V, s.time_s, s.iq_A, s.ud_V, s.id_A});
      true_r = s.true_resistance_ohm;
    }
    w.Close();
  }
  const Result r = Identify("good");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const tools::CsvTable out = tools::CsvTable::Read(TempPath("good.out.csv"));
  EXPECT_EQ(out.columns(), (std::vector<std::string>{"time_s", "resistance_ohm", "flux_Wb",
                                                     "winding_resistance_degC", "status",
                                                     "winding_resistance_sd_K", "flux_sd_Wb"}));
  EXPECT_EQ(out.rows(), 60000u);
  const auto rs = out.Column("resistance_ohm");
  const auto temp = out.Column("winding_resistance_degC");
  const auto status = out.Column("status");
  EXPECT_NEAR(rs.back(), true_r, 0.005 * true_r);
  EXPECT_NEAR(temp.back(), 45.0, 1.5);
  EXPECT_EQ(status.front(), 0.0);  // initialising
  for (double st : status) ASSERT_TRUE(st >= 0.0 && st <= 6.0 && st == std::floor(st)) << st;
  const auto sd = out.Column("winding_resistance_sd_K");
  for (std::size_t k = 100; k < sd.size(); ++k)
    ASSERT_TRUE(sd[k] > 0.0 && std::isfinite(sd[k])) << k;
  EXPECT_LT(sd.back(), 1.0) << "the last 1-sigma, K";
}

}  // namespace
TEST(IdentifyCli, ShortOptionsAndStandardOutputByDefault) {
  WriteText(TempPath("short.csv"), std::string(kHeader) + kRow1 + kRow2);
  const std::string out = TempPath("short.stdout");
  const std::string cmd = std::string("'") + PUMPTHERM_CLI + "' identify -i '" +
                          TempPath("short.csv") + "' > '" + out + "' 2>/dev/null";
  const int status = std::system(cmd.c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0);
  const std::string csv = ReadFile(out);
  EXPECT_EQ(csv.rfind("time_s,resistance_ohm", 0), 0u) << csv;
  EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 3) << csv;
}

}  // namespace pumptherm
