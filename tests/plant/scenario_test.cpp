// Scenario files of the plant simulator: parsing, defaults, groups, and errors that name where.
#include "tools/plant/scenario.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "tests/common/test_files.hpp"

namespace pumptherm::plant {
namespace {

constexpr const char* kMinimal = R"(
[scenario]
name = "t"
duration_s = 10
[defaults]
model = "tmp-generic"
[profile.p]
segments = [ { duration_s = 5, speed_rpm = 1000, iq_A = 2.0 }, { duration_s = 5, iq_A = 1.0, ambient_C = 30 } ]
[[pump]]
name = "a"
node_id = 3
profile = "p"
)";

std::string ErrorOf(const std::string& text) {
  try {
    ParseScenario(text, "s.toml");
  } catch (const ScenarioError& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(PlantScenario, ParsesDefaultsProfileAndSensors) {
  const Scenario sc = ParseScenario(kMinimal, "s.toml");
  EXPECT_EQ(sc.name, "t");
  EXPECT_DOUBLE_EQ(sc.duration_s, 10.0);
  ASSERT_EQ(sc.pumps.size(), 1u);
  const PumpSpec& p = sc.pumps[0];
  EXPECT_EQ(p.name, "a");
  EXPECT_EQ(p.node_id, 3u);
  EXPECT_EQ(p.model, "tmp-generic");
  EXPECT_EQ(p.motor, "han2019-tmp");
  EXPECT_EQ(p.interface, "can0");
  ASSERT_EQ(p.segments.size(), 2u);
  EXPECT_DOUBLE_EQ(p.segments[0].speed_rpm, 1000.0);
  EXPECT_TRUE(std::isnan(p.segments[1].speed_rpm));
  EXPECT_DOUBLE_EQ(p.segments[1].ambient_degC, 30.0);
  // Defaults of realistic-signals.md for the frame RTD.
  EXPECT_EQ(p.frame_sensor.node, "frame");
  EXPECT_DOUBLE_EQ(p.frame_sensor.accuracy_K, 0.35);
  EXPECT_DOUBLE_EQ(p.frame_sensor.resolution_K, 0.1);
  EXPECT_GE(p.frame_sensor.lag_s, 10.0);
}

TEST(PlantScenario, GroupExpandsNodeIdsNamesAndStagger) {
  const Scenario sc = ParseScenario(R"(
[scenario]
name = "g"
duration_s = 10
[[pump]]
name = "f"
model = "tmp-generic"
interface = "can1"
node_id = 2
count = 3
stagger_s = 4
segments = [ { duration_s = 5, speed_rpm = 1000 } ]
)",
                                    "g.toml");
  ASSERT_EQ(sc.pumps.size(), 3u);
  EXPECT_EQ(sc.pumps[0].name, "f02");
  EXPECT_EQ(sc.pumps[2].name, "f04");
  EXPECT_EQ(sc.pumps[2].node_id, 4u);
  EXPECT_EQ(sc.pumps[2].interface, "can1");
  EXPECT_EQ(sc.pumps[0].segments.size(), 1u);
  ASSERT_EQ(sc.pumps[2].segments.size(), 2u);
  EXPECT_DOUBLE_EQ(sc.pumps[2].segments[0].duration_s, 8.0);
}

TEST(PlantScenario, FaultsParse) {
  const Scenario sc = ParseScenario(std::string(kMinimal) + R"(faults = [
  { kind = "dropped_frames", start_s = 1, end_s = 2, probability = 0.5 },
  { kind = "stale_sensor", start_s = 3 },
  { kind = "stuck_sensor", start_s = 4, end_s = 5 },
  { kind = "cooling_failure", start_s = 6, edge = "cooling", factor = 5 },
  { kind = "sensor_offset", start_s = 9, offset_K = -2.5 } ]
[[bus_off]]
interface = "can0"
start_s = 7
end_s = 8
)",
                                    "s.toml");
  const auto& f = sc.pumps[0].faults;
  ASSERT_EQ(f.size(), 5u);
  EXPECT_EQ(f[0].kind, FaultKind::kDroppedFrames);
  EXPECT_DOUBLE_EQ(f[0].probability, 0.5);
  EXPECT_EQ(f[1].kind, FaultKind::kStaleSensor);
  EXPECT_TRUE(std::isinf(f[1].end_s));
  EXPECT_EQ(f[2].kind, FaultKind::kStuckSensor);
  EXPECT_EQ(f[3].kind, FaultKind::kCoolingFailure);
  EXPECT_EQ(f[3].edge, "cooling");
  EXPECT_DOUBLE_EQ(f[3].factor, 5.0);
  EXPECT_EQ(f[4].kind, FaultKind::kSensorOffset);
  EXPECT_DOUBLE_EQ(f[4].offset_K, -2.5);
  ASSERT_EQ(sc.bus_offs.size(), 1u);
  EXPECT_DOUBLE_EQ(sc.bus_offs[0].end_s, 8.0);
}

TEST(PlantScenario, TrueMotorRippleAndLoadDriftParse) {
  std::string text = kMinimal;
  text.replace(text.find("model = \"tmp-generic\"\n"), 22,
               "model = \"tmp-generic\"\nmotor_r0_scale = 1.02\n"
               "drive = { speed_ripple_rpm = 3.0, dead_time_V = 0.15 }\n");
  text.replace(text.find("iq_A = 1.0,"), 11, "iq_A = 1.0, iq_end_A = 1.5,");
  text += "motor_flux_scale = 0.984\ndrive = { speed_ripple_hz = 0.5 }\n";
  const Scenario sc = ParseScenario(text, "s.toml");
  const PumpSpec& p = sc.pumps.at(0);
  EXPECT_DOUBLE_EQ(p.motor_r0_scale, 1.02);  // from [defaults]
  EXPECT_DOUBLE_EQ(p.motor_flux_scale, 0.984);
  EXPECT_DOUBLE_EQ(p.drive.speed_ripple_rpm, 3.0);  // drive keys merge key by key
  EXPECT_DOUBLE_EQ(p.drive.speed_ripple_hz, 0.5);
  EXPECT_DOUBLE_EQ(p.drive.dead_time_V, 0.15);
  EXPECT_TRUE(std::isnan(p.segments.at(0).iq_end_A));
  EXPECT_DOUBLE_EQ(p.segments.at(1).iq_end_A, 1.5);
  // Without the keys: the nameplate motor, no ripple.
  const Scenario minimal = ParseScenario(kMinimal, "s.toml");
  const PumpSpec& q = minimal.pumps.at(0);
  EXPECT_DOUBLE_EQ(q.motor_r0_scale, 1.0);
  EXPECT_DOUBLE_EQ(q.motor_flux_scale, 1.0);
  EXPECT_DOUBLE_EQ(q.drive.speed_ripple_rpm, 0.0);

  EXPECT_NE(ErrorOf(std::string(kMinimal) + "motor_r0_scale = 3\n")
                .find("s.toml:13: pump[0].motor_r0_scale: 3 is outside [0.5, 2]"),
            std::string::npos)
      << ErrorOf(std::string(kMinimal) + "motor_r0_scale = 3\n");
  EXPECT_NE(ErrorOf(std::string(kMinimal) + "motor_flux_scale = \"x\"\n")
                .find("s.toml:13: pump[0].motor_flux_scale: expected a finite number"),
            std::string::npos);
  EXPECT_NE(ErrorOf(std::string(kMinimal) + "drive = { speed_ripple_hz = 0 }\n")
                .find("s.toml:13: pump[0].drive.speed_ripple_hz: 0 is outside"),
            std::string::npos)
      << ErrorOf(std::string(kMinimal) + "drive = { speed_ripple_hz = 0 }\n");
  EXPECT_NE(ErrorOf(std::string(kMinimal) + "drive = { speed_ripple_rpm = -1 }\n")
                .find("pump[0].drive.speed_ripple_rpm: -1 is outside"),
            std::string::npos);
  text = kMinimal;
  text.replace(text.find("iq_A = 1.0,"), 11, "iq_A = 1.0, iq_end_A = true,");
  EXPECT_NE(
      ErrorOf(text).find("s.toml:8: profile.p.segments[1].iq_end_A: expected a finite number"),
      std::string::npos)
      << ErrorOf(text);
}

TEST(PlantScenario, ProfileRepeatRunsTheSegmentsAgain) {
  std::string text = kMinimal;
  text.replace(text.find("[profile.p]\n"), 12, "[profile.p]\nrepeat = 3\n");
  const Scenario sc = ParseScenario(text, "s.toml");
  const auto& seg = sc.pumps.at(0).segments;
  ASSERT_EQ(seg.size(), 6u);
  for (std::size_t k = 0; k < 6; k += 2) {
    EXPECT_DOUBLE_EQ(seg[k].speed_rpm, 1000.0) << k;
    EXPECT_DOUBLE_EQ(seg[k + 1].ambient_degC, 30.0) << k;
  }
  text = kMinimal;
  text.replace(text.find("[profile.p]\n"), 12, "[profile.p]\nrepeat = 0\n");
  EXPECT_NE(ErrorOf(text).find("profile.p.repeat"), std::string::npos) << ErrorOf(text);
}

TEST(PlantScenario, ErrorsNameLineAndKey) {
  std::string text = kMinimal;
  text.replace(text.find("node_id = 3"), 11, "node_ib = 3");
  EXPECT_NE(ErrorOf(text).find("s.toml:11: pump[0].node_ib: unknown key"), std::string::npos)
      << ErrorOf(text);

  text = kMinimal;
  text.replace(text.find("node_id = 3"), 11, "node_id = 16");
  EXPECT_NE(ErrorOf(text).find("pump[0].node_id"), std::string::npos) << ErrorOf(text);

  text = kMinimal;
  text.replace(text.find("profile = \"p\""), 13, "profile = \"q\"");
  EXPECT_NE(ErrorOf(text).find("s.toml:12: pump[0].profile: no [profile.q]"), std::string::npos)
      << ErrorOf(text);

  text = std::string(kMinimal) + "faults = [ { kind = \"melted\" } ]\n";
  EXPECT_NE(ErrorOf(text).find("pump[0].faults[0].kind"), std::string::npos) << ErrorOf(text);
  text = std::string(kMinimal) + "faults = [ { kind = \"sensor_offset\", start_s = 1 } ]\n";
  EXPECT_NE(ErrorOf(text).find("pump[0].faults[0].offset_K: missing"), std::string::npos)
      << ErrorOf(text);
  text = std::string(kMinimal) + "faults = [ { kind = \"stuck_sensor\", offset_K = 1 } ]\n";
  EXPECT_NE(ErrorOf(text).find("only a sensor_offset has an offset_K"), std::string::npos)
      << ErrorOf(text);

  text = std::string(kMinimal) + "[[pump]]\nname = \"b\"\nnode_id = 3\nprofile = \"p\"\n";
  EXPECT_NE(ErrorOf(text).find("node ID 3 on can0 is used by another pump"), std::string::npos)
      << ErrorOf(text);

  text = kMinimal;
  text.replace(text.find("duration_s = 5, speed"), 14, "duration_s = -5");
  EXPECT_NE(ErrorOf(text).find("profile.p.segments[0].duration_s: must be positive"),
            std::string::npos)
      << ErrorOf(text);

  EXPECT_NE(ErrorOf("[scenario\n").find("s.toml:1:"), std::string::npos);
}

TEST(PlantScenario, BundledScenariosParse) {
  const char* dir = std::getenv("PUMPTHERM_SOURCE_DIR");
  ASSERT_NE(dir, nullptr);
  int bundled = 0;
  for (const auto& entry :
       std::filesystem::directory_iterator(std::string(dir) + "/tools/plant/scenarios")) {
    if (entry.path().extension() != ".toml") continue;
    const std::string path = entry.path().string();
    EXPECT_NO_THROW(ParseScenario(test_files::ReadFile(path), path)) << path;
    ++bundled;
  }
  EXPECT_GE(bundled, 13);
  const Scenario fleet = ParseScenario(
      test_files::ReadFile(std::string(dir) + "/tools/plant/scenarios/fleet32.toml"), "fleet32");
  EXPECT_EQ(fleet.pumps.size(), 32u);
  EXPECT_DOUBLE_EQ(fleet.duration_s, 3600.0);
  const Scenario week = ParseScenario(
      test_files::ReadFile(std::string(dir) + "/tools/plant/scenarios/fleet32-week.toml"),
      "fleet32-week");
  ASSERT_EQ(week.pumps.size(), 32u);
  EXPECT_DOUBLE_EQ(week.duration_s, 7 * 86400.0);
  for (const PumpSpec& p : week.pumps) {  // the daily cycle, seven times, after the group's stagger
    double total_s = 0.0;
    for (const auto& s : p.segments) total_s += s.duration_s;
    EXPECT_GE(total_s, 7 * 86400.0) << p.name;
    EXPECT_LE(total_s, 7 * 86400.0 + 6 * 20.0) << p.name;  // at most 6 x stagger_s (groups of 7)
  }
}

}  // namespace
}  // namespace pumptherm::plant
