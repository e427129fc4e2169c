// Robustness of the daemon's pipeline (issue 8, docs/robustness.md): inputs far outside any
// rating must not make the daemon publish a garbage temperature.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <sys/stat.h>
#include <unistd.h>

#include "daemon/config.hpp"
#include "daemon/pump.hpp"
#include "daemon/state_store.hpp"
#include "daemon/resources.hpp"
#include "estimators/motor.hpp"
#include "estimators/thermal_model.hpp"

namespace pumptherm::daemon {
namespace {

std::unique_ptr<Pump> MakePump() {
  PumpConfig pc;
  pc.name = "tmp1";
  pc.thermal_model = "tmp-generic";
  pc.measured_node = "frame";
  auto model = std::make_shared<const estimators::ThermalModel>(estimators::ThermalModel::Parse(
      ReadTextFile(ResolveResource(ResourceKind::kModel, "tmp-generic")), "tmp-generic"));
  return std::make_unique<Pump>(pc, estimators::MotorPreset("han2019-tmp"), model, 1.0);
}

// Found by pipeline_step_fuzz: currents far above any rating (here 20 A in d and q on a motor of a few
// amperes), held while the frame sensor falls silent, make the temperature-dependent copper loss
// outgrow the network's conduction (Saheba 2010 eqs. 12-16): the open-loop estimate ran away to
// 6e159 degC with an infinite standard deviation, and was published. Now such a filter is reset
// (counted) and nothing is published until it runs again.
TEST(PumpRobustness, RunawayEstimateIsResetNeverPublished) {
  auto pump = MakePump();
  const std::int64_t t0 = 1'700'000'000'000'000;
  pump->OnStatus(t0, 24000.0, 2.0, 25.0, 25.0);  // the frame sensor speaks once, then never again
  double hottest_published = -kInf;
  for (int k = 1; k <= 3000; ++k) {
    const std::int64_t t = t0 + std::int64_t{k} * 1'000'000;
    pump->OnCurrents(t, 20.0, 20.0, 2513.0, kNaN);
    pump->Advance(t);
    const PumpSnapshot& s = pump->snapshot();
    if (!s.initialised) continue;
    for (std::size_t i = 0; i < s.node_degC.size(); ++i) {
      ASSERT_TRUE(std::isfinite(s.node_degC[i]) && std::isfinite(s.node_sd_K[i]))
          << "state " << i << " at step " << k << ": " << s.node_degC[i] << " degC, sd " << s.node_sd_K[i];
      ASSERT_LE(s.node_degC[i], kMaxEstimate_degC) << "state " << i << " at step " << k;
      hottest_published = std::max(hottest_published, s.node_degC[i]);
    }
  }
  EXPECT_GT(pump->counters().filter_resets, 0U) << "the runaway was expected to happen here";
  EXPECT_GT(hottest_published, 200.0);  // it did run hot before the reset
  EXPECT_TRUE(pump->snapshot().alarm.trip_latched || pump->snapshot().alarm.level != estimators::AlarmLevel::kNone);
}

// Security (issue 8): a configuration anyone may write decides the alarm levels and who may
// clear trips, so the daemon warns about it; the saved state is the service's alone (0600).
TEST(FilePermissions, ConfigWritableByOthersIsWarnedAbout) {
  char dir_template[] = "/tmp/pumptherm-perm-XXXXXX";
  ASSERT_NE(::mkdtemp(dir_template), nullptr);
  const std::string path = std::string(dir_template) + "/p.toml";
  WriteFileAtomically(path, "", 0644);
  EXPECT_EQ(ConfigPermissionWarning(path), "");
  ASSERT_EQ(::chmod(path.c_str(), 0600), 0);
  EXPECT_EQ(ConfigPermissionWarning(path), "");
  ASSERT_EQ(::chmod(path.c_str(), 0664), 0);
  EXPECT_NE(ConfigPermissionWarning(path).find("writable by its group (mode 0664)"), std::string::npos)
      << ConfigPermissionWarning(path);
  ASSERT_EQ(::chmod(path.c_str(), 0666), 0);
  EXPECT_NE(ConfigPermissionWarning(path).find("writable by group and others (mode 0666)"), std::string::npos);
  EXPECT_EQ(ConfigPermissionWarning(std::string(dir_template) + "/missing.toml"), "");
  ::unlink(path.c_str());

  const std::string state = std::string(dir_template) + "/state.toml";
  const mode_t old_umask = ::umask(0);  // the mode must not depend on the caller's umask
  WriteFileAtomically(state, "version = 1\n");
  ::umask(old_umask);
  struct stat st {};
  ASSERT_EQ(::stat(state.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 07777, 0600U);
  ::unlink(state.c_str());
  ::rmdir(dir_template);
}

}  // namespace
}  // namespace pumptherm::daemon
