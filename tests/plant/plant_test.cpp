// The plant simulator end to end on short scenarios: determinism, the frames decode back through
// the DBC to the simulated values, rolling counters, jitter bounds, faults, cooling failure.
#include "tools/plant/plant.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "protocol/candump_log.hpp"
#include "protocol/codec.hpp"
#include "protocol/dbc.hpp"
#include "tests/common/test_files.hpp"
#include "tools/common/csv.hpp"

namespace pumptherm::plant {
namespace {

using pumptherm::test_files::ReadFile;

namespace fs = std::filesystem;

std::string SourceDir() {
  const char* d = std::getenv("PUMPTHERM_SOURCE_DIR");
  return d != nullptr ? d : ".";
}

PlantResources Resources() {
  PlantResources r;
  r.model = [](const std::string& ref) {
    const fs::path p = fs::path(SourceDir()) / "estimators" / "models" / (ref + ".toml");
    if (!fs::exists(p)) throw std::runtime_error("no model " + p.string());
    return LoadedText{ReadFile(p), p.string()};
  };
  r.motor_file = [](const std::string& ref) -> LoadedText {
    throw std::runtime_error("no motor file " + ref);
  };
  const fs::path proto = fs::path(SourceDir()) / "protocol";
  r.dbc = {ReadFile(proto / "pumptherm.dbc"), "pumptherm.dbc"};
  r.mapping = {ReadFile(proto / "mapping_pumptherm.toml"), "mapping_pumptherm.toml"};
  return r;
}

fs::path OutDir(const std::string& name) {
  const fs::path d = fs::path(testing::TempDir()) / ("pumptherm_plant_" + name);
  fs::remove_all(d);
  return d;
}

/// Two pumps on can0, one on can1, 30 s: a run-up and a load step; `faults` go to pump "a".
std::string ScenarioText(const std::string& faults = "", const std::string& extra = "",
                         int seed = 7) {
  return R"(
[scenario]
name = "t"
duration_s = 30
seed = )" +
         std::to_string(seed) + R"(
jitter_sd_us = 100
jitter_max_us = 300
[defaults]
model = "tmp-generic"
initial_C = 40
[profile.p]
segments = [ { duration_s = 10, speed_rpm = 21000, iq_A = 3.0 }, { duration_s = 20, iq_A = 2.0 } ]
[[pump]]
name = "a"
node_id = 1
profile = "p"
faults = [ )" +
         faults + R"( ]
[[pump]]
name = "b"
node_id = 2
profile = "p"
[[pump]]
name = "c"
interface = "can1"
node_id = 1
profile = "p"
)" + extra;
}

PlantResult RunScenario(const std::string& text, const fs::path& out) {
  const plant::Scenario sc = ParseScenario(text, "test.toml");
  return RunPlant(sc, Resources(), out.string());
}

/// A decoded frame of the log.
struct Decoded {
  std::int64_t time_us;
  std::string interface;
  std::uint32_t id;
  std::string message;
  std::map<std::string, double> values;
};

std::vector<Decoded> DecodeLog(const fs::path& path) {
  const protocol::Dbc dbc =
      protocol::ParseDbc(ReadFile(fs::path(SourceDir()) / "protocol" / "pumptherm.dbc"), "dbc");
  const protocol::DbcCodec codec(dbc);
  std::vector<Decoded> out;
  std::ifstream f(path);
  std::string line;
  while (std::getline(f, line)) {
    const protocol::CandumpParse p = protocol::ParseCandumpLine(line);
    EXPECT_TRUE(p.ok) << line << ": " << p.error;
    if (!p.ok) continue;
    // Pump n sends at the DBC's ID + n: find the message by the ID's block of 16.
    const std::uint32_t base = p.record.frame.id & ~0xFu;
    const int mi = codec.Find(base, false);
    EXPECT_GE(mi, 0) << line;
    if (mi < 0) continue;
    const auto& msg = dbc.messages[static_cast<std::size_t>(mi)];
    std::vector<double> v(msg.signals.size());
    EXPECT_EQ(
        codec.message(static_cast<std::size_t>(mi))
            .Decode(std::span<const std::uint8_t>(p.record.frame.data.data(), p.record.frame.len),
                    v),
        protocol::CodecStatus::kOk);
    Decoded d{p.record.time_us, std::string(p.record.interface), p.record.frame.id, msg.name, {}};
    for (std::size_t i = 0; i < v.size(); ++i) d.values[msg.signals[i].name] = v[i];
    out.push_back(std::move(d));
  }
  return out;
}

std::vector<Decoded> Select(const std::vector<Decoded>& all, const std::string& iface,
                            std::uint32_t id) {
  std::vector<Decoded> out;
  for (const Decoded& d : all) {
    if (d.interface == iface && d.id == id) out.push_back(d);
  }
  return out;
}

constexpr std::int64_t kEpochUs = 1767225600LL * 1000000;

TEST(Plant, SameSeedSameBytesOtherSeedOtherBytes) {
  const fs::path a = OutDir("det_a"), b = OutDir("det_b"), c = OutDir("det_c");
  RunScenario(ScenarioText(), a);
  RunScenario(ScenarioText(), b);
  RunScenario(ScenarioText("", "", 8), c);
  for (const char* f : {"t.log", "a.truth.csv", "a.measured.csv", "c.truth.csv", "summary.json"}) {
    const std::string x = ReadFile(a / f), y = ReadFile(b / f);
    ASSERT_FALSE(x.empty()) << f;
    EXPECT_EQ(std::hash<std::string>{}(x), std::hash<std::string>{}(y)) << f;
  }
  EXPECT_NE(std::hash<std::string>{}(ReadFile(a / "t.log")),
            std::hash<std::string>{}(ReadFile(c / "t.log")));
}

TEST(Plant, FramesDecodeToTheSimulatedValues) {
  const fs::path out = OutDir("decode");
  const PlantResult r = RunScenario(ScenarioText(), out);
  const auto frames = DecodeLog(out / "t.log");
  EXPECT_EQ(frames.size(), r.frames_written);
  // 3 pumps x 30 s x (100 + 100 + 10) frames per second.
  EXPECT_EQ(frames.size(), 3u * 30u * 210u);
  const tools::CsvTable measured = tools::CsvTable::Read((out / "a.measured.csv").string());
  const auto t = measured.Time();
  const auto iq = measured.Column("iq_A");
  const auto id = measured.Column("id_A");
  const auto speed = measured.Column("speed_rpm");
  const auto frame = measured.Column("frame_degC");
  const auto fast = Select(frames, "can0", 0x100 + 1);
  const auto volts = Select(frames, "can0", 0x110 + 1);
  const auto status = Select(frames, "can0", 0x180 + 1);
  ASSERT_EQ(fast.size(), 3000u);
  ASSERT_EQ(volts.size(), 3000u);
  ASSERT_EQ(status.size(), 300u);
  for (std::size_t row = 0; row < t.size(); ++row) {
    const auto k = static_cast<std::size_t>(std::llround(t[row] / 0.01));
    const Decoded& f = fast[k];
    // Within half a DBC step (5 mA, 0.01 rad/s, 0.1 K) of what the drive reported.
    EXPECT_NEAR(f.values.at("Iq_A"), iq[row], 0.0025 + 1e-9) << "t " << t[row];
    EXPECT_NEAR(f.values.at("Id_A"), id[row], 0.0025 + 1e-9) << "t " << t[row];
    EXPECT_NEAR(f.values.at("SpeedElec_rad_per_s"), speed[row] * 2.0 * M_PI / 60.0, 0.005 + 1e-9);
    const Decoded& s = status[k / 10];
    EXPECT_NEAR(s.values.at("FrameSensor_degC"), frame[row], 0.05 + 1e-9) << "t " << t[row];
    EXPECT_NEAR(s.values.at("SpeedMech_rpm"), speed[row], 1.0 + 1e-9);
  }
  // The physics behind the frames: at rated speed uq is the back-EMF w psi plus Rs iq
  // (Han 2019 eq. 4), within the voltage noise and quantisation.
  const tools::CsvTable truth = tools::CsvTable::Read((out / "a.truth.csv").string());
  const auto rs = truth.Column("resistance_ohm");
  const auto tt = truth.Time();
  for (std::size_t row = 15; row < tt.size(); ++row) {
    const auto k = static_cast<std::size_t>(std::llround(tt[row] / 0.01));
    const double w = fast[k].values.at("SpeedElec_rad_per_s");
    const double expected = rs[row] * fast[k].values.at("Iq_A") + w * 0.0182;
    EXPECT_NEAR(volts[k].values.at("Uq_V"), expected, 0.08) << "t " << tt[row];
  }
  // Drive state: accelerating during the run-up, then steady.
  EXPECT_EQ(status[20].values.at("DriveState"), 1.0);
  EXPECT_EQ(status[200].values.at("DriveState"), 2.0);
}

TEST(Plant, RollingCountersIncrementAndWrap) {
  const fs::path out = OutDir("counter");
  RunScenario(ScenarioText(), out);
  const auto frames = DecodeLog(out / "t.log");
  for (std::uint32_t base : {0x100u, 0x180u}) {
    const auto f = Select(frames, "can0", base + 2);
    ASSERT_GT(f.size(), 100u);
    int wraps = 0;
    for (std::size_t i = 1; i < f.size(); ++i) {
      const double prev = f[i - 1].values.at("RollingCounter"),
                   cur = f[i].values.at("RollingCounter");
      EXPECT_EQ(cur, std::fmod(prev + 1.0, 16.0)) << "frame " << i;
      if (cur == 0.0) ++wraps;
    }
    EXPECT_GT(wraps, 0);
  }
  // PUMP_FAST_U carries the counter of the PUMP_FAST_I of the same control step.
  const auto fi = Select(frames, "can0", 0x102), fu = Select(frames, "can0", 0x112);
  ASSERT_EQ(fi.size(), fu.size());
  for (std::size_t i = 0; i < fi.size(); ++i) {
    ASSERT_EQ(fi[i].values.at("RollingCounter"), fu[i].values.at("RollingCounter"));
    ASSERT_GT(fu[i].time_us, fi[i].time_us);
  }
}

TEST(Plant, JitterStaysWithinBoundsAndLogIsTimeOrdered) {
  const fs::path out = OutDir("jitter");
  RunScenario(ScenarioText(), out);
  const auto frames = DecodeLog(out / "t.log");
  for (std::size_t i = 1; i < frames.size(); ++i)
    ASSERT_GE(frames[i].time_us, frames[i - 1].time_us) << i;
  const auto f = Select(frames, "can1", 0x101);
  ASSERT_EQ(f.size(), 3000u);
  // Nominal time of step k: epoch + k 10 ms + a fixed phase; the phase is the mean offset.
  double mean = 0.0;
  for (std::size_t k = 0; k < f.size(); ++k)
    mean += static_cast<double>(f[k].time_us - kEpochUs - static_cast<std::int64_t>(k) * 10000);
  mean /= static_cast<double>(f.size());
  double max_dev = 0.0, sum2 = 0.0;
  for (std::size_t k = 0; k < f.size(); ++k) {
    const double dev =
        static_cast<double>(f[k].time_us - kEpochUs - static_cast<std::int64_t>(k) * 10000) - mean;
    max_dev = std::max(max_dev, std::abs(dev));
    sum2 += dev * dev;
  }
  const double sd = std::sqrt(sum2 / static_cast<double>(f.size()));
  EXPECT_LE(max_dev, 300.0 + 5.0);  // bound 300 us, the mean estimate off by a few us
  EXPECT_NEAR(sd, 100.0, 15.0);     // jitter_sd_us = 100, slightly less for the clamping
  EXPECT_GE(mean, -1.0);
  EXPECT_LT(mean, 10000.0);
}

TEST(Plant, DroppedFramesAreMissing) {
  const fs::path out = OutDir("dropped");
  const PlantResult r = RunScenario(
      ScenarioText(R"({ kind = "dropped_frames", start_s = 5, end_s = 10, probability = 1.0 },
      { kind = "dropped_frames", start_s = 20, end_s = 25, probability = 0.3 })"),
      out);
  const auto frames = DecodeLog(out / "t.log");
  const auto a = Select(frames, "can0", 0x101);
  const auto b = Select(frames, "can0", 0x102);
  EXPECT_EQ(b.size(), 3000u);
  std::size_t in_full = 0, in_partial = 0, gaps = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    const double t_s = static_cast<double>(a[i].time_us - kEpochUs) / 1e6;
    if (t_s >= 5.01 && t_s < 9.99) ++in_full;
    if (t_s >= 20.01 && t_s < 24.99) ++in_partial;
    if (i > 0 && a[i].values.at("RollingCounter") !=
                     std::fmod(a[i - 1].values.at("RollingCounter") + 1.0, 16.0))
      ++gaps;
  }
  EXPECT_EQ(in_full, 0u);
  EXPECT_NEAR(static_cast<double>(in_partial), 0.7 * 500.0, 50.0);
  EXPECT_GT(gaps, 50u);  // the counter shows the losses
  EXPECT_GT(r.pumps[0].frames_suppressed, 0u);
  EXPECT_EQ(r.pumps[1].frames_suppressed, 0u);
}

TEST(Plant, StaleSensorStopsStatusFrames) {
  const fs::path out = OutDir("stale");
  RunScenario(ScenarioText(R"({ kind = "stale_sensor", start_s = 12, end_s = 20 })"), out);
  const auto frames = DecodeLog(out / "t.log");
  std::size_t during = 0, after = 0;
  for (const Decoded& d : Select(frames, "can0", 0x181)) {
    const double t_s = static_cast<double>(d.time_us - kEpochUs) / 1e6;
    if (t_s >= 12.01 && t_s < 19.99) ++during;
    if (t_s >= 20.01) ++after;
  }
  EXPECT_EQ(during, 0u);
  EXPECT_GT(after, 90u);
  EXPECT_EQ(Select(frames, "can0", 0x182).size(), 300u);   // pump b unaffected
  EXPECT_EQ(Select(frames, "can0", 0x101).size(), 3000u);  // fast frames continue
  const tools::CsvTable m = tools::CsvTable::Read((out / "a.measured.csv").string());
  const auto frame = m.ColumnAllowingNaN("frame_degC");
  EXPECT_TRUE(std::isnan(frame[15]));
  EXPECT_FALSE(std::isnan(frame[25]));
}

TEST(Plant, StuckSensorHoldsItsValueWhileTheFrameHeats) {
  const fs::path out = OutDir("stuck");
  RunScenario(ScenarioText(R"({ kind = "stuck_sensor", start_s = 10 })", "", 7), out);
  const auto frames = DecodeLog(out / "t.log");
  std::vector<double> stuck, free_running;
  for (const Decoded& d : Select(frames, "can0", 0x181)) {
    if (static_cast<double>(d.time_us - kEpochUs) / 1e6 > 10.05)
      stuck.push_back(d.values.at("FrameSensor_degC"));
  }
  for (const Decoded& d : Select(frames, "can0", 0x182)) {
    if (static_cast<double>(d.time_us - kEpochUs) / 1e6 > 10.05)
      free_running.push_back(d.values.at("FrameSensor_degC"));
  }
  ASSERT_GT(stuck.size(), 150u);
  for (double v : stuck) EXPECT_EQ(v, stuck.front());
  const auto [lo, hi] = std::minmax_element(free_running.begin(), free_running.end());
  EXPECT_GT(*hi - *lo, 0.1);  // the healthy sensor moves (noise and heating)
}

TEST(Plant, SensorOffsetShiftsTheReadingWhileItLasts) {
  const fs::path out = OutDir("offset");
  RunScenario(ScenarioText(
                  R"({ kind = "sensor_offset", start_s = 10, end_s = 15, offset_K = 3.0 })", "", 7),
              out);
  const auto frames = DecodeLog(out / "t.log");
  // Pump 1's reading against pump 2's (same profile, same truth but for their sensors' noise
  // and drawn calibration): 3 K higher while the fault lasts, not before or after.
  auto mean_between = [&](std::uint32_t id, double a_s, double b_s) {
    double sum = 0.0;
    int n = 0;
    for (const Decoded& d : Select(frames, "can0", id)) {
      const double t_s = static_cast<double>(d.time_us - kEpochUs) / 1e6;
      if (t_s > a_s && t_s < b_s) {
        sum += d.values.at("FrameSensor_degC");
        ++n;
      }
    }
    return n > 0 ? sum / n : std::nan("");
  };
  const double before = mean_between(0x181, 5.0, 9.9) - mean_between(0x182, 5.0, 9.9);
  const double during = mean_between(0x181, 10.1, 14.9) - mean_between(0x182, 10.1, 14.9);
  const double after = mean_between(0x181, 15.1, 19.9) - mean_between(0x182, 15.1, 19.9);
  EXPECT_NEAR(during - before, 3.0, 0.3);
  EXPECT_NEAR(after - before, 0.0, 0.3);
}

TEST(Plant, BusOffSilencesEveryPumpOnTheInterface) {
  const fs::path out = OutDir("busoff");
  RunScenario(ScenarioText("", "[[bus_off]]\ninterface = \"can0\"\nstart_s = 14\nend_s = 16.5\n"),
              out);
  const auto frames = DecodeLog(out / "t.log");
  std::int64_t last_before = 0, first_after = INT64_MAX;
  std::size_t can1_during = 0;
  for (const Decoded& d : frames) {
    const double t_s = static_cast<double>(d.time_us - kEpochUs) / 1e6;
    if (d.interface == "can0") {
      ASSERT_FALSE(t_s >= 14.02 && t_s < 16.49) << "frame at " << t_s;
      if (t_s < 14.02) last_before = std::max(last_before, d.time_us);
      if (t_s >= 16.49) first_after = std::min(first_after, d.time_us);
    } else if (t_s >= 14.02 && t_s < 16.49) {
      ++can1_during;
    }
  }
  EXPECT_GE(first_after - last_before, 2'400'000);  // a gap of about 2.5 s
  EXPECT_GT(can1_during, 400u);                     // can1 unaffected
}

TEST(Plant, CoolingFailureRaisesTemperatures) {
  const fs::path ok = OutDir("cool_ok"), failed = OutDir("cool_failed");
  RunScenario(ScenarioText(), ok);
  RunScenario(
      ScenarioText(R"({ kind = "cooling_failure", start_s = 5, edge = "cooling", factor = 20 })"),
      failed);
  const tools::CsvTable a = tools::CsvTable::Read((ok / "a.truth.csv").string());
  const tools::CsvTable b = tools::CsvTable::Read((failed / "a.truth.csv").string());
  const double frame_ok = a.Column("frame_degC").back(),
               frame_failed = b.Column("frame_degC").back();
  // 25 s of lost cooling: the frame keeps its heat (tens of W on 300 J/K: about 1 K more).
  EXPECT_GT(frame_failed - frame_ok, 0.5) << frame_ok << " vs " << frame_failed;
  EXPECT_EQ(b.Column("cooling_model").back(), 1.0);
  EXPECT_EQ(b.Column("cooling_model").front(), 0.0);
}

TEST(Plant, EffectsWithAStartChangeTheTruthFromThen) {
  const fs::path ok = OutDir("effect_ok"), later = OutDir("effect_later");
  RunScenario(ScenarioText(), ok);
  // Pump c: 44 W more on the rotor at 21000 r/min from 15 s on.
  RunScenario(
      ScenarioText("", R"(effects = [ { name = "rotor_loss", values = [0.1], start_s = 15 } ])"),
      later);
  const tools::CsvTable a = tools::CsvTable::Read((ok / "c.truth.csv").string());
  const tools::CsvTable b = tools::CsvTable::Read((later / "c.truth.csv").string());
  const auto& t = b.Column("time_s");
  const auto& rotor_ok = a.Column("rotor_degC");
  const auto& rotor = b.Column("rotor_degC");
  ASSERT_EQ(rotor.size(), rotor_ok.size());
  for (std::size_t i = 0; i < t.size() && t[i] < 15.0; ++i) {
    ASSERT_EQ(rotor[i], rotor_ok[i]) << "t " << t[i] << " s: the effect began early";
  }
  EXPECT_GT(rotor.back() - rotor_ok.back(), 1.0) << rotor_ok.back() << " vs " << rotor.back();
  EXPECT_EQ(b.Column("cooling_model").front(), 0.0);
  EXPECT_EQ(b.Column("cooling_model").back(), 1.0);
  // One onset per pump, and not beside a cooling failure (one changed model at a time).
  EXPECT_THROW(ParseScenario(ScenarioText("", R"(effects = [
    { name = "rotor_loss", values = [0.1], start_s = 15 },
    { name = "iron_loss_scale", values = [1.2], start_s = 16 } ])"),
                             "test.toml"),
               plant::ScenarioError);
  EXPECT_THROW(ParseScenario(ScenarioText("", R"(
[[pump]]
name = "d"
node_id = 3
profile = "p"
faults = [ { kind = "cooling_failure", start_s = 5, edge = "cooling", factor = 2 } ]
effects = [ { name = "rotor_loss", values = [0.1], start_s = 15 } ])"),
                             "test.toml"),
               plant::ScenarioError);
}

TEST(Plant, WindingTemperatureFeedsTheResistance) {
  const fs::path out = OutDir("rs");
  RunScenario(ScenarioText(), out);
  const tools::CsvTable t = tools::CsvTable::Read((out / "b.truth.csv").string());
  const auto rs = t.Column("resistance_ohm");
  const auto tw = t.Column("winding_resistance_degC");
  const auto winding = t.Column("winding_degC");
  for (std::size_t i = 0; i < rs.size(); ++i) {
    EXPECT_NEAR(rs[i], 0.28 * (1.0 + 4.1e-3 * (tw[i] - 27.2)), 1e-9);  // Han 2019 eq. 2
    EXPECT_NEAR(tw[i], winding[i], 1e-9);  // tmp-generic: one winding node
  }
}

/// One pump ("a", 40 s: a 10 s run-up, then 2 A, then a gas load drifting from 2 to 3 A) with
/// the given keys added to the pump, and a nameplate twin ("b") without them.
std::string TrueMotorScenario(const std::string& keys) {
  return R"(
[scenario]
name = "m"
duration_s = 40
seed = 3
[defaults]
model = "tmp-generic"
initial_C = 40
[profile.p]
segments = [ { duration_s = 10, speed_rpm = 21000, iq_A = 3.0 }, { duration_s = 20, iq_A = 2.0 },
             { duration_s = 10, iq_A = 2.0, iq_end_A = 3.0 } ]
[[pump]]
name = "a"
node_id = 1
profile = "p"
)" + keys +
         R"(
[[pump]]
name = "b"
node_id = 2
profile = "p"
)";
}

TEST(Plant, TrueMotorDiffersFromTheNameplateInResistanceFluxAndLosses) {
  const fs::path out = OutDir("true_motor");
  RunScenario(TrueMotorScenario("motor_r0_scale = 1.1\nmotor_flux_scale = 0.95\n"), out);
  const tools::CsvTable a = tools::CsvTable::Read((out / "a.truth.csv").string());
  const tools::CsvTable b = tools::CsvTable::Read((out / "b.truth.csv").string());
  const auto rs = a.Column("resistance_ohm"), tw = a.Column("winding_resistance_C");
  const auto flux = a.Column("flux_Wb");
  const auto loss_a = a.Column("loss_winding_W"), loss_b = b.Column("loss_winding_W");
  const auto tw_b = b.Column("winding_resistance_C");
  auto copper = [](double t_degC) { return 1.0 + 4.1e-3 * (t_degC - 27.2); };  // Han 2019 eq. 2
  for (std::size_t i = 0; i < rs.size(); ++i) {
    EXPECT_NEAR(rs[i], 1.1 * 0.28 * copper(tw[i]), 1e-9) << i;
    EXPECT_NEAR(flux[i], 0.95 * 0.0182, 1e-12) << i;  // no magnet node: the flux is constant
    // Same true currents in both pumps: the copper loss is 1.1 times the nameplate's law.
    if (loss_b[i] > 0.0) {
      EXPECT_NEAR(loss_a[i] / copper(tw[i]), 1.1 * loss_b[i] / copper(tw_b[i]), 1e-9) << i;
    }
  }
  EXPECT_NEAR(b.Column("resistance_ohm")[5], 0.28 * copper(tw_b[5]), 1e-9);
}

TEST(Plant, GasLoadDriftsWithinASegment) {
  const fs::path out = OutDir("drift");
  RunScenario(TrueMotorScenario(""), out);
  const tools::CsvTable a = tools::CsvTable::Read((out / "a.truth.csv").string());
  const auto t = a.Time();
  const auto iq = a.Column("iq_A");
  for (std::size_t i = 0; i < t.size(); ++i) {
    if (t[i] < 31.0) continue;
    // The set point ramps 0.1 A/s from 2 A at 30 s; the current loop (0.2 s) lags it by 0.02 A.
    EXPECT_NEAR(iq[i], 2.0 + 0.1 * (t[i] - 30.0) - 0.1 * 0.2, 2e-3) << "t " << t[i];
  }
  EXPECT_NEAR(iq[25], 2.0, 1e-6);  // constant where no end value is given
}

TEST(Plant, DeadTimeAndSpeedRippleAreInUqNotInTheReportedSpeed) {
  const fs::path out = OutDir("ripple");
  constexpr double kDeadTimeV = 0.2, kRippleRpm = 30.0, kRippleHz = 0.5;
  RunScenario(TrueMotorScenario("drive = { dead_time_V = 0.2, speed_ripple_rpm = 30.0, "
                                "speed_ripple_hz = 0.5 }\n"),
              out);
  const auto frames = DecodeLog(out / "m.log");
  const auto fast = Select(frames, "can0", 0x101);
  const auto volts = Select(frames, "can0", 0x111);
  ASSERT_EQ(fast.size(), 4000u);
  ASSERT_EQ(volts.size(), 4000u);
  const tools::CsvTable truth = tools::CsvTable::Read((out / "a.truth.csv").string());
  const auto rs = truth.Column("resistance_ohm");
  // From 12 s to 30 s at 2 A (the current settled): uq against Han 2019 eq. 4 at the nominal
  // speed plus the dead-time voltage (tanh law along the current); what is left is noise,
  // quantisation and the back-EMF of the speed ripple. Its amplitude, by correlation with the
  // ripple's sine over whole periods, is w_ripple psi_f.
  const double w0 = 21000.0 * 2.0 * M_PI / 60.0;
  const double dead_q = kDeadTimeV * std::tanh(2.0 / 0.5);
  double mean = 0.0, sin_sum = 0.0, speed_sin_sum = 0.0;
  int n = 0;
  for (int k = 1200; k < 3000; ++k) {
    const double t_s = 0.01 * k;
    const double expected = rs[static_cast<std::size_t>(k / 100)] * 2.0 + w0 * 0.0182 + dead_q;
    const double r = volts[static_cast<std::size_t>(k)].values.at("Uq_V") - expected;
    const double s = std::sin(2.0 * M_PI * kRippleHz * t_s);
    mean += r;
    sin_sum += r * s;
    speed_sin_sum += fast[static_cast<std::size_t>(k)].values.at("SpeedElec_rad_per_s") * s;
    ++n;
  }
  mean /= n;
  const double ripple_V = 2.0 * sin_sum / n;
  const double speed_ripple_rpm = 2.0 * speed_sin_sum / n * 60.0 / (2.0 * M_PI);
  const double expected_V = kRippleRpm * 2.0 * M_PI / 60.0 * 0.0182;  // 57 mV
  EXPECT_NEAR(mean, 0.0, 0.005) << "dead time and eq. 4 explain the mean of uq";
  EXPECT_NEAR(ripple_V, expected_V, 0.005);
  EXPECT_LT(std::abs(speed_ripple_rpm), 0.5) << "the speed estimate shows no mechanical ripple";
}

TEST(Plant, ScaleCopperLosses) {
  const std::string model = R"(
[[loss]]
name = "copper"
power_W = "r0_ohm * i2_A2"
temperature_coefficient_per_K = 4.1e-3
shares = { w = 1 }
[[loss]]
name = "iron"
power_W = 20.0
shares = { s = 1 }
)";
  const std::string scaled = ScaleCopperLosses(model, "m", 1.02);
  EXPECT_NE(scaled.find("(r0_ohm * i2_A2) * 1.02"), std::string::npos) << scaled;
  EXPECT_NE(scaled.find("power_W = 20.0"), std::string::npos) << scaled;  // iron untouched
  try {
    ScaleCopperLosses("[[loss]]\nname = \"iron\"\npower_W = 3.0\n", "m.toml", 1.02);
    FAIL();
  } catch (const ScenarioError& e) {
    EXPECT_NE(std::string(e.what()).find("m.toml: no copper loss"), std::string::npos) << e.what();
  }
}

TEST(Plant, ScaleEdgeResistance) {
  const std::string model = R"(
[[node]]
name = "x"
capacity_J_per_K = 1
[[edge]]
name = "e"
between = ["x", "ambient"]
resistance_K_per_W = 2.0
[[edge]]
between = ["x", "y"]
resistance_K_per_W = "1 + speed_rpm"
)";
  EXPECT_NE(ScaleEdgeResistance(model, "m", "e", 3.0).find("resistance_K_per_W = 6.0"),
            std::string::npos);
  EXPECT_NE(ScaleEdgeResistance(model, "m", "y-x", 3.0).find("(1 + speed_rpm) * 3"),
            std::string::npos);
  try {
    ScaleEdgeResistance(model, "m", "z", 3.0);
    FAIL();
  } catch (const ScenarioError& e) {
    EXPECT_NE(std::string(e.what()).find("no edge named 'z' (edges: e, x-y)"), std::string::npos)
        << e.what();
  }
}

TEST(Plant, UnknownNodeIsAnError) {
  const fs::path out = OutDir("badnode");
  std::string text = ScenarioText();
  text.replace(text.find("initial_C = 40"), 14,
               "initial_C = 40\nframe_sensor = { node = \"housing\" }");
  try {
    RunScenario(text, out);
    FAIL();
  } catch (const ScenarioError& e) {
    EXPECT_NE(std::string(e.what()).find("has no node 'housing'"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace pumptherm::plant
