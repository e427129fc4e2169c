// Robustness of the daemon's pipeline (docs/robustness.md): inputs far outside any
// rating must not make the daemon publish a garbage temperature.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <memory>
#include <sstream>
#include <string>

#include "daemon/config.hpp"
#include "daemon/gateway.hpp"
#include "daemon/live_loop.hpp"
#include "daemon/offline.hpp"
#include "daemon/pump.hpp"
#include "daemon/resources.hpp"
#include "daemon/state_store.hpp"
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

// Runs one pump for `steps` seconds on currents far above any rating and asserts that nothing
// non-finite or above kMaxEstimate_degC is ever published; returns the hottest published node.
double RunOverloaded(double current_A, double speed_rpm, bool sensor_speaks, int steps,
                     std::unique_ptr<Pump>& pump) {
  pump = MakePump();
  const std::int64_t t0 = 1'700'000'000'000'000;
  pump->OnStatus(t0, 24000.0, 2.0, 25.0, 25.0);
  double hottest_published = -kInf;
  for (int k = 1; k <= steps; ++k) {
    const std::int64_t t = t0 + std::int64_t{k} * 1'000'000;
    pump->OnCurrents(t, current_A, current_A, speed_rpm, kNaN);
    if (sensor_speaks) pump->OnStatus(t, 24000.0, 2.0, 25.0, 25.0);
    pump->Advance(t);
    const PumpSnapshot& s = pump->snapshot();
    if (!s.initialised) continue;
    for (std::size_t i = 0; i < s.node_degC.size(); ++i) {
      EXPECT_TRUE(std::isfinite(s.node_degC[i]) && std::isfinite(s.node_sd_K[i]))
          << "state " << i << " at step " << k << ": " << s.node_degC[i] << " degC, sd "
          << s.node_sd_K[i];
      EXPECT_LE(s.node_degC[i], kMaxEstimate_degC) << "state " << i << " at step " << k;
      if (testing::Test::HasFailure()) return hottest_published;
      hottest_published = std::max(hottest_published, s.node_degC[i]);
    }
  }
  return hottest_published;
}

// Found by pipeline_step_fuzz: currents far above any rating (here 20 A in d and q on a motor of a
// few amperes), held while the frame sensor falls silent, make the temperature-dependent copper
// loss outgrow the network's conduction (Saheba 2010 eqs. 12-16): the open-loop estimate ran away
// to 6e159 degC with an infinite standard deviation, and was published. Now such a filter is reset
// (counted) and nothing is published until it runs again.
TEST(PumpRobustness, RunawayEstimateIsResetNeverPublished) {
  std::unique_ptr<Pump> pump;
  const double hottest = RunOverloaded(20.0, 2513.0, false, 3000, pump);
  EXPECT_GT(pump->counters().filter_resets, 0U) << "the runaway was expected to happen here";
  EXPECT_GT(hottest, 200.0);  // it did run hot before the reset
  EXPECT_TRUE(pump->snapshot().alarm.trip_latched ||
              pump->snapshot().alarm.level != estimators::AlarmLevel::kNone);
}

// Found by pipeline_step_fuzz: 30 A at 30000 r/min with the frame sensor speaking. The runaway
// winding is reset again and again; once, the disturbance-state filter's winding sd overflowed
// while its mean (and the standard filter) were still finite, and the infinite sd was published.
TEST(PumpRobustness, OverflowedDisturbanceSdIsResetNeverPublished) {
  std::unique_ptr<Pump> pump;
  RunOverloaded(30.0, 30000.0, true, 4000, pump);
  EXPECT_GT(pump->counters().filter_resets, 0U) << "the runaway was expected to happen here";
}

// Offline, the log's stamps are the clock: a stamp a little behind (another interface) is taken
// at the later time; the recording host's clock set back 200 s holds time and then runs on at the
// pace of the new stamps; a forward step is elapsed time.
TEST(PipelineClock, OfflineBackwardStepHoldsThenRunsOn) {
  OfflineClock c;
  const std::int64_t t0 = 1'767'225'600'000'000;
  EXPECT_EQ(c.Now(t0), t0);
  EXPECT_EQ(c.Now(t0 + 1'000'000), t0 + 1'000'000);
  EXPECT_EQ(c.Now(t0 + 999'000), t0 + 1'000'000);        // 1 ms out of order
  EXPECT_EQ(c.Now(t0 - 199'000'000), t0 + 1'000'000);    // set back 200 s
  EXPECT_EQ(c.Now(t0 - 198'000'000), t0 + 2'000'000);    // runs on, 1 s later
  EXPECT_EQ(c.Now(t0 + 100'000'000), t0 + 300'000'000);  // forward: elapsed
  EXPECT_EQ(c.steps_back(), 1u);                         // the 1 ms reorder is no step
  EXPECT_EQ(c.last_step_back_us(), 199'999'000);         // from the stamp just before it
}

// Two logs concatenated: the second's stamps go back. Warned with the line, counted, and its
// frames used (the pipeline's time holds at the step).
TEST(PipelineClock, TwoConcatenatedLogsAreWarnedAndCounted) {
  const std::string log =
      "(1767225600.000000) can0 123#00\n(1767225660.000000) can0 123#00\n"
      "(1767225000.000000) can0 123#00\n(1767225001.000000) can0 123#00\n";
  std::istringstream in(log);
  Gateway g(ParseConfig("[[can]]\ninterface = \"can0\"\n", "p.toml"));
  testing::internal::CaptureStderr();
  const OfflineResult r = RunOffline(in, "two.log", g);
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_EQ(r.frames, 4u);
  EXPECT_EQ(r.time_steps_back, 1u);
  EXPECT_NE(err.find("two.log:3: time goes back 660.000 s"), std::string::npos) << err;
}

// Live, the kernel's receive stamps are wall time: mapped to the monotonic clock, they stay in
// [previous frame, now] whatever the wall clock did between a frame's arrival and its reading.
TEST(PipelineClock, KernelStampsMapToTheMonotonicClock) {
  const std::int64_t wall = 1'767'225'600'000'000;
  const std::int64_t mono = 5'000'000'000;
  EXPECT_EQ(MonotonicStampUs(wall - 3'000, wall, mono, -1), mono - 3'000);
  // The wall clock was set back 200 s after the frame arrived: it looks 200 s in the future.
  EXPECT_EQ(MonotonicStampUs(wall - 3'000, wall - 200'000'000, mono, mono - 10'000), mono);
  // Set forward 200 s: it looks 200 s old, but not older than the frame before it.
  EXPECT_EQ(MonotonicStampUs(wall - 3'000, wall + 200'000'000, mono, mono - 10'000), mono - 10'000);
  EXPECT_EQ(MonotonicStampUs(0, wall, mono, mono - 10'000), mono);  // no stamp
}

// A frozen frame sensor is found by its flat noise, dropped from the filter (the sd grows) and
// raised as a sensor fault; a silent one is found by its age, the fast frames going on.
TEST(PumpRobustness, FrozenAndSilentSensorsAreFaultsAndLeftOut) {
  for (const bool frozen : {true, false}) {
    auto pump = MakePump();
    const std::int64_t t0 = 1'700'000'000'000'000;
    double sd_when_failed = kNaN;
    for (int k = 0; k < 1200; ++k) {  // 120 s at 10 Hz: the sensor fails at 30 s
      const std::int64_t t = t0 + std::int64_t{k} * 100'000;
      pump->OnCurrents(t, 0.0, 3.0, 2513.0, kNaN);
      const bool failed = k >= 300;
      if (failed && std::isnan(sd_when_failed)) sd_when_failed = pump->snapshot().node_sd_K[0];
      const double live = 40.0 + 0.1 * (k % 3);
      if (!failed || frozen) pump->OnStatus(t, 24000.0, 2.0, failed ? 40.0 : live, 25.0);
      pump->Advance(t);
    }
    const PumpSnapshot& s = pump->snapshot();
    const char* what = frozen ? "frozen" : "silent";
    EXPECT_EQ(s.sensor_fault,
              frozen ? estimators::SensorFault::kStuck : estimators::SensorFault::kMissing)
        << what;
    EXPECT_TRUE(std::isnan(s.frame_measured_degC)) << what << ": a failed sensor must not be fused";
    EXPECT_TRUE(s.alarm.active_reasons &
                (1U << static_cast<unsigned>(estimators::AlarmReason::kSensorFault)))
        << what;
    EXPECT_GT(s.node_sd_K[0], sd_when_failed)
        << what << ": the frame's sd must grow without its sensor";
  }
}

// The drive's fast frames arrive but no status frame ever does (no frame temperature, no
// ambient): the filter cannot start, yet the sensor's absence is a sensor fault, raised within
// stale_after_s plus the hold, and no temperature is published.
TEST(PumpRobustness, ASensorNeverHeardIsAFaultBeforeAnyEstimate) {
  auto pump = MakePump();
  const std::int64_t t0 = 1'700'000'000'000'000;
  double raised_s = kNaN;
  for (int k = 0; k < 600; ++k) {  // 60 s at 10 Hz
    const std::int64_t t = t0 + std::int64_t{k} * 100'000;
    pump->OnCurrents(t, 0.0, 3.0, 2513.0, kNaN);
    pump->Advance(t);
    const PumpSnapshot& s = pump->snapshot();
    ASSERT_FALSE(s.initialised) << "no temperature was ever heard";
    const bool fault = s.alarm.active_reasons &
                       (1U << static_cast<unsigned>(estimators::AlarmReason::kSensorFault));
    if (fault && std::isnan(raised_s)) raised_s = k * 0.1;
  }
  EXPECT_LE(raised_s, 6.0) << "raised at " << raised_s << " s";
  EXPECT_EQ(pump->snapshot().alarm.level, estimators::AlarmLevel::kWarning);
  // One change (none to the sensor-fault warning) is one change: a state whose value is NaN is
  // the same state at the next step (each counted change is a journal line and an LCM message).
  EXPECT_LE(pump->snapshot().alarm_changes, 2U);
}

// The time the daemon was down is a telemetry silence (docs/daemon.md, "The pipeline, per
// pump"): a pump saved at 5 A that is heard again at 12 A 300 s later may have run 12 A all that
// time, so it trips at once (winding trip level 110 degC; 12 A for 300 s from about 70 degC goes
// far above it); heard again at once, its estimate (about 70 degC) only starts rising.
TEST(PumpRobustness, ARestartIsATelemetrySilence) {
  auto level_after_restart = [](std::int64_t down_us) {
    PumpConfig pc;
    pc.name = "tmp1";
    pc.measured_node = "frame";
    pc.alarms.levels["winding"].limits = {100.0, 110.0};
    auto model = std::make_shared<const estimators::ThermalModel>(estimators::ThermalModel::Parse(
        ReadTextFile(ResolveResource(ResourceKind::kModel, "tmp-generic")), "tmp-generic"));
    const auto motor = estimators::MotorPreset("han2019-tmp");
    // frames FROM_US STEPS IQ_A: 10 Hz currents and a live frame reading, then Advance.
    auto frames = [](Pump& p, std::int64_t from_us, int steps, double iq_A) {
      for (int k = 0; k < steps; ++k) {
        const std::int64_t t = from_us + std::int64_t{k} * 100'000;
        p.OnCurrents(t, 0.0, iq_A, 2199.0, kNaN);
        p.OnStatus(t, 21000.0, 2.0, 46.6 + 0.1 * (k % 3), 22.0);
        p.Advance(t);
      }
    };
    const std::int64_t t0 = 1'700'000'000'000'000;
    Pump before(pc, motor, model, 1.0);
    frames(before, t0, 2000, 5.0);  // 200 s at 5 A
    EXPECT_EQ(before.snapshot().alarm.level, estimators::AlarmLevel::kNone);
    const PumpSavedState saved = before.Save();
    Pump after(pc, motor, model, 1.0);
    EXPECT_TRUE(after.Restore(saved, saved.time_us + down_us));
    frames(after, saved.time_us + down_us + 100'000, 50, 12.0);  // 5 s at 12 A
    return after.snapshot().alarm;
  };
  const estimators::AlarmState late = level_after_restart(300'000'000);
  EXPECT_EQ(late.level, estimators::AlarmLevel::kTrip) << "value " << late.value;
  const estimators::AlarmState at_once = level_after_restart(0);
  EXPECT_NE(at_once.level, estimators::AlarmLevel::kTrip) << "value " << at_once.value;
}

// Security: a configuration anyone may write decides the alarm levels and who may
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
  EXPECT_NE(ConfigPermissionWarning(path).find("writable by its group (mode 0664)"),
            std::string::npos)
      << ConfigPermissionWarning(path);
  ASSERT_EQ(::chmod(path.c_str(), 0666), 0);
  EXPECT_NE(ConfigPermissionWarning(path).find("writable by group and others (mode 0666)"),
            std::string::npos);
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
