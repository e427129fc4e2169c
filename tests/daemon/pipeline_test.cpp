// The gateway pipeline on recorded frames: a pump's telemetry, synthesised from a thermal truth
// through the shipped DBC, goes through decode, resistance identification, the virtual thermal
// sensor, alarms, CAN encoding and LCM encoding.
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <toml++/toml.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <lcm/lcm-cpp.hpp>
#include <map>
#include <numbers>
#include <regex>
#include <set>
#include <sstream>

#include "daemon/gateway.hpp"
#include "daemon/lcm_bridge.hpp"
#include "daemon/log.hpp"
#include "daemon/resources.hpp"
#include "protocol/codec.hpp"
#include "protocol/dbc.hpp"
#include "pumptherm/alarm_clear_t.hpp"
#include "pumptherm/alarm_t.hpp"
#include "pumptherm/gateway_health_t.hpp"
#include "pumptherm/telemetry_t.hpp"
#include "pumptherm/temperatures_t.hpp"
#include "tools/sim/thermal_plant.hpp"

namespace pumptherm::daemon {
namespace {

constexpr double kPsi_Wb = 0.0182;
constexpr double kR_ohm = 0.28;

/// Records what the gateway sends.
struct RecordingSink : OutputSink {
  std::vector<std::pair<std::int64_t, protocol::CanFrame>> frames;
  std::multimap<std::string, std::vector<std::uint8_t>> lcm;
  void SendFrame(std::size_t, std::int64_t t, const protocol::CanFrame& f) override {
    frames.emplace_back(t, f);
  }
  bool PublishLcm(const std::string& ch, std::int64_t,
                  const std::vector<std::uint8_t>& b) override {
    lcm.emplace(ch, b);
    return true;
  }
};

/// The operator's key (listed in Config as "panel") and the gateway's.
SigningKey PanelKey() { return SigningKey(Seed{7, 1, 8}); }
SigningKey GatewayKey() { return SigningKey(Seed{7, 9, 9}); }

std::string Config(const std::string& extra = "") {
  return R"(
[gateway]
heartbeat_period_s = 0

[[can]]
interface = "can0"

[alarms]
hold_s = 2
# The bench's frame sensor is the noiseless truth: steady, it repeats its value to the bit, so
# the flat-noise test for a stuck sensor does not apply to it.
flat_after_s = 0
[[alarms.clear_operators]]
name = "panel"
public_key = ")" +
         FormatPublicKey(PanelKey().public_key()) + R"("

[[pump]]
name = "tmp1"
node_id = 1
interface = "can0"
motor = "han2019-tmp"
thermal_model = "saheba2010-improved"
measured_node = "frame"
)" + extra;
}

/// A clear command for pump tmp1 of gateway "pumptherm", signed with the panel's key.
pumptherm::alarm_clear_t SignedClear(std::int64_t utime, std::int64_t counter,
                                     const std::string& comment) {
  pumptherm::alarm_clear_t m;
  m.utime = utime;
  m.gateway = "pumptherm";
  m.pump = "tmp1";
  m.node = "";
  m.comment = comment;
  m.counter = counter;
  SignCommand(PanelKey(), GatewayKey().public_key(), "PUMPTHERM", m);
  return m;
}

/// Gives `g` the gateway's key and the operators' of its configuration.
void Keyed(Gateway& g) {
  g.SetGatewayKey(GatewayKey());
  g.LoadClearKeys("");
}

/// Drives a gateway with 100 Hz fast frames and 10 Hz status frames of a pump at 800 r/min and
/// `iq_A`, whose temperatures come from the improved Saheba model (the filter's own model).
class Bench {
 public:
  /// `plant_degC`: the plant's start (empty: every node at 25 degC), e.g. another bench's truth
  /// for a restart.
  explicit Bench(const std::string& config_text, const Eigen::VectorXd& plant_degC = {})
      : config_(ParseConfig(config_text,
                            std::string(PUMPTHERM_SOURCE_DIR) + "/tests/daemon/pipeline.toml")),
        gateway_(config_),
        dbc_(protocol::ParseDbc(ReadTextFile(ResolveResource(ResourceKind::kDbc, "pumptherm.dbc")),
                                "pumptherm.dbc")),
        codec_(dbc_),
        model_(estimators::ThermalModel::Parse(
            ReadTextFile(ResolveResource(ResourceKind::kModel, "saheba2010-improved")),
            "improved")),
        plant_(model_,
               plant_degC.size() > 0 ? plant_degC
                                     : Eigen::VectorXd::Constant(model_.StateCount(), 25.0),
               {.process_sd_K = 0.0}, 7) {
    iface_ = gateway_.Interface("can0");
  }

  void Frame(const char* message, std::int64_t t_us, const std::map<std::string, double>& values) {
    const protocol::DbcMessage* m = dbc_.FindMessage(message);
    ASSERT_NE(m, nullptr);
    const int index = static_cast<int>(m - dbc_.messages.data());
    const auto& codec = codec_.message(static_cast<std::size_t>(index));
    std::vector<double> v(codec.signal_count(), 0.0);
    for (const auto& [name, value] : values)
      v[static_cast<std::size_t>(m->FindSignal(name))] = value;
    protocol::TimedFrame tf;
    tf.time_us = t_us;
    tf.frame.id = m->id + 1;  // node 1
    tf.frame.len = static_cast<std::uint8_t>(codec.min_bytes());
    codec.Encode(v, std::span<std::uint8_t>(tf.frame.data.data(), tf.frame.len));
    gateway_.OnFrame(iface_, tf);
    gateway_.Advance(t_us, sink);
  }

  /// The GW_NODE_TEMP frames sent for node 1, decoded: signal name -> value, in send order.
  std::vector<std::map<std::string, double>> NodeFrames() const { return Frames("GW_NODE_TEMP"); }

  /// Every frame of the message `name` sent for node ID 1, decoded, by signal name.
  std::vector<std::map<std::string, double>> Frames(const std::string& name) const {
    std::vector<std::map<std::string, double>> out;
    const protocol::DbcMessage* m = dbc_.FindMessage(name);
    const auto& codec = codec_.message(static_cast<std::size_t>(m - dbc_.messages.data()));
    for (const auto& [t, f] : sink.frames) {
      if (f.id != m->id + 1) continue;
      std::vector<double> v(codec.signal_count());
      if (codec.Decode(std::span<const std::uint8_t>(f.data.data(), f.len), v) !=
          protocol::CodecStatus::kOk)
        continue;
      std::map<std::string, double> named;
      for (std::size_t i = 0; i < v.size(); ++i) named[m->signals[i].name] = v[i];
      out.push_back(std::move(named));
    }
    return out;
  }

  /// Runs `seconds` at `iq_A`.
  void Run(double seconds, double iq_A) {
    const double w = 800.0 / 60.0 * 2.0 * std::numbers::pi;  // one pole pair
    const int steps = static_cast<int>(seconds * 100.0);
    for (int k = 0; k < steps; ++k) {
      const std::int64_t t = t_us_ + 10'000;
      t_us_ = t;
      // The winding resistance follows the truth's winding temperature (Han 2019 eq. 2 with the
      // han2019-tmp preset's R0 at T0 and alpha), so identification and model agree.
      const double t_w = truth_.size() ? 0.5 * (truth_(3) + truth_(4)) : 25.0;
      const double r_ohm = kR_ohm * (1.0 + 4.1e-3 * (t_w - 27.2));
      const double uq = r_ohm * iq_A + w * kPsi_Wb;
      const double c = counter_++ % 16;
      Frame("PUMP_FAST_I", t,
            {{"Id_A", 0.0}, {"Iq_A", iq_A}, {"SpeedElec_rad_per_s", w}, {"RollingCounter", c}});
      Frame("PUMP_FAST_U", t + 200,
            {{"Ud_V", -w * 0.24e-3 * iq_A}, {"Uq_V", uq}, {"RollingCounter", c}});
      if (k % 10 == 0) {
        plant_.Step(
            {.speed_rpm = 800.0, .id_A = 0.0, .iq_A = iq_A, .ambient_degC = truth_ambient_degC},
            0.1);
        truth_ = plant_.State_degC();
        Frame("PUMP_STATUS", t + 400,
              {{"SpeedMech_rpm", 800.0},
               {"DriveState", 2.0},
               {"FrameSensor_degC", truth_(0) + frame_offset_K},
               {"Ambient_degC", 25.0},
               {"DcLink_V", 48.0},
               {"RollingCounter", static_cast<double>(k / 10 % 16)}});
      } else {
        plant_.Step(
            {.speed_rpm = 800.0, .id_A = 0.0, .iq_A = iq_A, .ambient_degC = truth_ambient_degC},
            0.0 + 1e-9);
      }
    }
  }

  DaemonConfig config_;
  Gateway gateway_;
  protocol::Dbc dbc_;
  protocol::DbcCodec codec_;
  estimators::ThermalModel model_;
  sim::ThermalPlant plant_;
  RecordingSink sink;
  Eigen::VectorXd truth_;
  double truth_ambient_degC = 25.0;  ///< the plant's ambient (the status frames always say 25)
  double frame_offset_K = 0.0;       ///< added to the frame reading (a sensor fault)
  std::size_t iface_ = 0;
  std::int64_t t_us_ = 1'763'776'800'000'000;
  int counter_ = 0;
};

TEST(Pipeline, EstimatesFollowTheTruthAndGoOutOnCanAndLcm) {
  Bench b(Config());
  b.Run(900.0, 40.0);
  const Pump& pump = *b.gateway_.pumps()[0];
  const PumpSnapshot& s = pump.snapshot();
  ASSERT_TRUE(s.initialised);
  EXPECT_EQ(pump.counters().lost_frames, 0U);
  EXPECT_EQ(pump.counters().unpaired, 0U);
  EXPECT_GE(pump.counters().thermal_steps, 895U);
  for (int i = 0; i < b.truth_.size(); ++i) {
    EXPECT_NEAR(s.node_degC[static_cast<std::size_t>(i)], b.truth_(i), 1.5)
        << pump.model().StateNames()[static_cast<std::size_t>(i)];
  }
  // The resistance identifier sees the resistance of the synthetic drive's winding.
  const double t_w = 0.5 * (b.truth_(3) + b.truth_(4));
  EXPECT_NEAR(s.resistance.resistance_ohm, kR_ohm * (1.0 + 4.1e-3 * (t_w - 27.2)), 0.01)
      << estimators::ToString(s.resistance.status);

  // GW_TEMPS_A for node 1 (ID 0x401) at 1 Hz, decoding to the estimates.
  const protocol::DbcMessage* temps = b.dbc_.FindMessage("GW_TEMPS_A");
  int count = 0;
  protocol::CanFrame last{};
  for (const auto& [t, f] : b.sink.frames) {
    if (f.id == temps->id + 1) {
      ++count;
      last = f;
    }
  }
  EXPECT_NEAR(count, 900, 2);
  const auto& codec = b.codec_.message(static_cast<std::size_t>(temps - b.dbc_.messages.data()));
  std::vector<double> v(codec.signal_count());
  ASSERT_EQ(codec.Decode(std::span<const std::uint8_t>(last.data.data(), last.len), v),
            protocol::CodecStatus::kOk);
  EXPECT_NEAR(v[static_cast<std::size_t>(temps->FindSignal("Frame_degC"))], s.node_degC[0], 0.02);
  EXPECT_NEAR(v[static_cast<std::size_t>(temps->FindSignal("Teeth_degC"))], s.node_degC[2], 0.02);

  // GW_NODE_TEMP: the last second's frames carry every node of the model, in turn, with its
  // sd; seven a second, as GW_TEMPS_A's one.
  const auto node_frames = b.NodeFrames();
  EXPECT_NEAR(static_cast<double>(node_frames.size()), 7.0 * count, 7.0 * 2);
  ASSERT_GE(node_frames.size(), 7u);
  std::set<std::size_t> seen;
  for (std::size_t i = node_frames.size() - 7; i < node_frames.size(); ++i) {
    const auto& f = node_frames[i];
    const auto node = static_cast<std::size_t>(f.at("NodeIndex"));
    ASSERT_LT(node, 7u);
    seen.insert(node);
    if (i > node_frames.size() - 7) {
      EXPECT_EQ(node, (static_cast<std::size_t>(node_frames[i - 1].at("NodeIndex")) + 1) % 7);
    }
    EXPECT_EQ(f.at("NodeCount"), 7.0);
    EXPECT_NEAR(f.at("NodeTemp_degC"), s.node_degC[node], 0.02);
    EXPECT_NEAR(f.at("NodeSd_K"), s.node_sd_K[node], 0.002);
    EXPECT_GT(f.at("NodeSd_K"), 0.0);
  }
  EXPECT_EQ(seen.size(), 7u);

  // Every LCM type, decodable, with the node names of the model.
  ASSERT_TRUE(b.sink.lcm.count("PUMPTHERM/tmp1/TEMPS"));
  ASSERT_TRUE(b.sink.lcm.count("PUMPTHERM/tmp1/TELEMETRY"));
  ASSERT_TRUE(b.sink.lcm.count("PUMPTHERM/tmp1/ALARM"));
  ASSERT_TRUE(b.sink.lcm.count("PUMPTHERM/GATEWAY/HEALTH"));
  const auto& bytes = std::prev(b.sink.lcm.upper_bound("PUMPTHERM/tmp1/TEMPS"))->second;
  pumptherm::temperatures_t m;
  ASSERT_GT(m.decode(bytes.data(), 0, static_cast<int>(bytes.size())), 0);
  EXPECT_EQ(m.pump, "tmp1");
  ASSERT_EQ(m.num_nodes, 7);
  EXPECT_EQ(m.node_names[3], "slot_winding");
  EXPECT_NEAR(m.node_degC[3], s.node_degC[3], 1e-9);
  EXPECT_EQ(m.filter_status, pumptherm::temperatures_t::FILTER_TRACKING);
}

std::string GenericConfig(const std::string& dbc_section = "") {
  std::string c = Config();
  c.replace(c.find("saheba2010-improved"), std::string("saheba2010-improved").size(),
            "tmp-generic");
  return dbc_section + c;
}

TEST(Pipeline, EveryNodeOfTheDefaultModelReachesCanWithItsSd) {
  Bench b(GenericConfig());
  b.Run(30.0, 5.0);  // tmp-generic is not the plant's model: a light load keeps it in range
  const auto& s = b.gateway_.pumps()[0]->snapshot();
  ASSERT_TRUE(s.initialised);
  ASSERT_EQ(s.node_degC.size(), 4u);  // frame, stator, winding, rotor
  const auto frames = b.NodeFrames();
  ASSERT_GE(frames.size(), 4u);
  std::set<double> seen;
  for (std::size_t i = frames.size() - 4; i < frames.size(); ++i) {
    const auto node = static_cast<std::size_t>(frames[i].at("NodeIndex"));
    ASSERT_LT(node, 4u);
    seen.insert(static_cast<double>(node));
    EXPECT_EQ(frames[i].at("NodeCount"), 4.0);
    EXPECT_NEAR(frames[i].at("NodeTemp_degC"), s.node_degC[node], 0.02) << node;
    EXPECT_NEAR(frames[i].at("NodeSd_K"), s.node_sd_K[node], 0.002) << node;
  }
  EXPECT_EQ(seen.size(), 4u);
}

// The disturbance-state filter keeps a large sd on a node the frame barely sees (the rotor,
// without the flux) by design: LCM's filter_status says whether the filter has converged, as the
// alarms judge it, not whether every published sd is small.
TEST(Pipeline, ALargeRotorSdIsNotAFilterStillConverging) {
  Bench b(GenericConfig());
  b.Run(300.0, 5.0);
  const auto& s = b.gateway_.pumps()[0]->snapshot();
  ASSERT_TRUE(s.initialised);
  ASSERT_GT(s.node_sd_K[3], 5.0) << "this test needs a rotor sd above the converged limit";
  EXPECT_TRUE(s.filter_converged);
  const auto& bytes = std::prev(b.sink.lcm.upper_bound("PUMPTHERM/tmp1/TEMPS"))->second;
  pumptherm::temperatures_t m;
  ASSERT_GT(m.decode(bytes.data(), 0, static_cast<int>(bytes.size())), 0);
  EXPECT_EQ(m.filter_status, pumptherm::temperatures_t::FILTER_TRACKING);
}

// The resistance-based winding temperature's sd goes out only with the temperature: while the
// identifier runs but publishes no winding temperature (held, converging), GW_IDENT_SD says "not
// available", not a saturated 65.534 K.
TEST(Pipeline, WindingResistanceSdIsNotAvailableWithoutItsTemperature) {
  Bench b(GenericConfig());
  b.Run(30.0, 5.0);
  const auto& s = b.gateway_.pumps()[0]->snapshot();
  ASSERT_NE(s.resistance.status, estimators::ResistanceStatus::kInitialising);
  ASSERT_TRUE(std::isnan(s.winding_resistance_degC))
      << "this test needs an identifier without a published winding temperature; status "
      << estimators::ToString(s.resistance.status);
  const auto frames = b.Frames("GW_IDENT_SD");
  ASSERT_FALSE(frames.empty());
  EXPECT_TRUE(std::isnan(frames.back().at("WindingResistanceSd_K")))
      << frames.back().at("WindingResistanceSd_K");
}

TEST(Pipeline, ANodeWithoutCanOutputIsAConfigurationErrorNamingIt) {
  // The shipped mapping without the default outputs (so without the node-indexed message):
  // tmp-generic's stator has no signal.
  std::string mapping =
      ReadTextFile(std::string(PUMPTHERM_SOURCE_DIR) + "/protocol/mapping_pumptherm.toml");
  std::istringstream in(mapping);
  std::string line, kept;
  while (std::getline(in, line)) {
    kept += line + "\n";
    if (line == "[outputs]") kept += "defaults = false\n";
  }
  const std::string path = ::testing::TempDir() + "pumptherm_mapping_no_node_table.toml";
  std::ofstream(path) << kept;
  const std::string config =
      GenericConfig("[dbc]\nfile = \"pumptherm.dbc\"\nmapping = \"" + path + "\"\n");
  try {
    const Gateway g(
        ParseConfig(config, std::string(PUMPTHERM_SOURCE_DIR) + "/tests/daemon/pipeline.toml"));
    ADD_FAILURE() << "accepted a model node without CAN output";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(
                  "pump[0].thermal_model': node 'stator' of tmp-generic has no CAN output"),
              std::string::npos)
        << e.what();
  }
  std::remove(path.c_str());
}

TEST(Pipeline, TheHealthMessageCarriesTheMqttSinksDrops) {
  Gateway g(ParseConfig(GenericConfig(""),
                        std::string(PUMPTHERM_SOURCE_DIR) + "/tests/daemon/pipeline.toml"));
  pumptherm::gateway_health_t m;
  auto bytes = g.EncodeHealth(1'000'000);
  ASSERT_GT(m.decode(bytes.data(), 0, static_cast<int>(bytes.size())), 0);
  EXPECT_FALSE(m.mqtt_enabled);
  EXPECT_EQ(m.mqtt_dropped, 0);
  g.SetMqttHealth({true, false, 441, 2});
  bytes = g.EncodeHealth(2'000'000);
  ASSERT_GT(m.decode(bytes.data(), 0, static_cast<int>(bytes.size())), 0);
  EXPECT_TRUE(m.mqtt_enabled);
  EXPECT_FALSE(m.mqtt_connected);
  EXPECT_EQ(m.mqtt_dropped, 441);
  EXPECT_EQ(m.mqtt_alarms_dropped, 2);
}

/// The last GW_ALARM of node 1, decoded: (MismatchState, MismatchEffect).
std::pair<double, double> LastMismatchOnCan(const Bench& b) {
  const protocol::DbcMessage* alarm = b.dbc_.FindMessage("GW_ALARM");
  protocol::CanFrame last{};
  for (const auto& [t, f] : b.sink.frames) {
    if (f.id == alarm->id + 1) last = f;
  }
  const auto& codec = b.codec_.message(static_cast<std::size_t>(alarm - b.dbc_.messages.data()));
  std::vector<double> v(codec.signal_count());
  EXPECT_EQ(codec.Decode(std::span<const std::uint8_t>(last.data.data(), last.len), v),
            protocol::CodecStatus::kOk);
  return {v[static_cast<std::size_t>(alarm->FindSignal("MismatchState"))],
          v[static_cast<std::size_t>(alarm->FindSignal("MismatchEffect"))]};
}

pumptherm::alarm_t LastAlarmOnLcm(const Bench& b) {
  const auto& bytes = std::prev(b.sink.lcm.upper_bound("PUMPTHERM/tmp1/ALARM"))->second;
  pumptherm::alarm_t m;
  EXPECT_GT(m.decode(bytes.data(), 0, static_cast<int>(bytes.size())), 0);
  return m;
}

TEST(Pipeline, DisturbanceStatesPublishAndTheModelIsFoundConsistent) {
  Bench b(Config("disturbance_states = true\n"));
  b.Run(900.0, 40.0);
  const Pump& pump = *b.gateway_.pumps()[0];
  const PumpSnapshot& s = pump.snapshot();
  ASSERT_TRUE(s.initialised);
  for (int i = 0; i < b.truth_.size(); ++i) {
    const auto k = static_cast<std::size_t>(i);
    EXPECT_NEAR(s.node_degC[k], b.truth_(i), 1.5) << pump.model().StateNames()[k];
    EXPECT_GE(s.node_sd_K[k], 1.0) << "the 1 K floor";
  }
  // The filter's own model as the truth: the mismatch test passes, on LCM and CAN.
  EXPECT_EQ(s.mismatch.state, estimators::MismatchState::kConsistent)
      << estimators::DescribeFinding(s.mismatch);
  const pumptherm::alarm_t m = LastAlarmOnLcm(b);
  EXPECT_EQ(m.mismatch_state, pumptherm::alarm_t::MISMATCH_CONSISTENT);
  EXPECT_EQ(m.mismatch_effect, pumptherm::alarm_t::EFFECT_NONE);
  EXPECT_EQ(LastMismatchOnCan(b).first, 0.0);
}

// Unset, disturbance_states follows the model (estimators::BoundaryOnlyThrough): the Saheba
// machine's boundary reaches it through the frame alone, so it is on; a written value stands.
TEST(Pipeline, DisturbanceStatesDefaultFollowsTheModel) {
  EXPECT_TRUE(Bench(Config()).gateway_.pumps()[0]->disturbance_states());
  EXPECT_FALSE(Bench(Config("disturbance_states = false\n"))
                   .gateway_.pumps()[0]
                   ->config()
                   .disturbance_states);
  // Measured on the rotor, the boundary (at the frame) reaches another node: off unless written.
  const std::string rotor = std::regex_replace(Config(), std::regex("measured_node = \"frame\""),
                                               "measured_node = \"rotor\"");
  EXPECT_FALSE(Bench(rotor).gateway_.pumps()[0]->disturbance_states());
  EXPECT_TRUE(Bench(rotor + "disturbance_states = true\n")
                  .gateway_.pumps()[0]
                  ->config()
                  .disturbance_states);
}

TEST(Pipeline, AnUnmeasuredAmbientRiseIsAPlantChangeNotAnImplausibleSensor) {
  Bench b(Config());
  b.Run(900.0, 40.0);
  ASSERT_EQ(b.gateway_.pumps()[0]->snapshot().mismatch.state,
            estimators::MismatchState::kConsistent);
  b.truth_ambient_degC = 33.0;  // the room warms by 8 K; the ambient sensor still says 25
  b.Run(600.0, 40.0);
  const PumpSnapshot& s = b.gateway_.pumps()[0]->snapshot();
  EXPECT_EQ(s.mismatch.state, estimators::MismatchState::kPlantChange)
      << estimators::DescribeFinding(s.mismatch);
  EXPECT_EQ(s.alarm.active_reasons &
                (1u << static_cast<unsigned>(estimators::AlarmReason::kImplausibleSensor)),
            0u);
  const pumptherm::alarm_t m = LastAlarmOnLcm(b);
  EXPECT_EQ(m.mismatch_state, pumptherm::alarm_t::MISMATCH_PLANT_CHANGE);
  EXPECT_EQ(m.mismatch_effect, static_cast<std::int8_t>(s.mismatch.effect));
  EXPECT_TRUE(std::isfinite(m.mismatch_value));
  const auto [state, effect] = LastMismatchOnCan(b);
  EXPECT_EQ(state, 2.0);
  EXPECT_EQ(effect, static_cast<double>(s.mismatch.effect));
}

TEST(Pipeline, AFrameSensorJumpIsASuspectedSensorFault) {
  Bench b(Config());
  b.Run(900.0, 40.0);
  b.frame_offset_K = 3.0;
  b.Run(120.0, 40.0);
  const PumpSnapshot& s = b.gateway_.pumps()[0]->snapshot();
  EXPECT_EQ(s.mismatch.state, estimators::MismatchState::kSensorFaultSuspected)
      << estimators::DescribeFinding(s.mismatch);
  EXPECT_EQ(s.mismatch.effect, estimators::MismatchEffect::kSensorOffset);
  EXPECT_NEAR(s.mismatch.value, 3.0, 0.5);
  EXPECT_EQ(LastAlarmOnLcm(b).mismatch_state, pumptherm::alarm_t::MISMATCH_SENSOR_FAULT_SUSPECTED);
  EXPECT_EQ(LastMismatchOnCan(b).first, 3.0);
}

// A frame reading that steps 3 K is an offset of the sensor: the published frame stays on the
// truth, implausible_sensor "offset" is raised, and both outlive a restart (saved state).
TEST(Pipeline, AFrameSensorStepIsAnOffsetThatOutlivesARestart) {
  constexpr unsigned kImplausible =
      1U << static_cast<unsigned>(estimators::AlarmReason::kImplausibleSensor);
  Bench b(Config());
  b.Run(900.0, 40.0);
  EXPECT_EQ(b.gateway_.pumps()[0]->snapshot().sensor_steps, 0U);
  EXPECT_EQ(b.gateway_.pumps()[0]->snapshot().alarm.active_reasons & kImplausible, 0U);
  b.frame_offset_K = 3.0;
  b.Run(30.0, 40.0);
  const PumpSnapshot& s = b.gateway_.pumps()[0]->snapshot();
  EXPECT_EQ(s.sensor_steps, 1U);
  EXPECT_NEAR(s.stepped_offset_K, 3.0, 0.3);
  EXPECT_NEAR(s.node_degC[0], b.truth_(0), 1.0) << "the published frame followed the step";
  EXPECT_NE(s.alarm.active_reasons & kImplausible, 0U);
  const std::string text = b.gateway_.SaveState();
  EXPECT_NE(text.find("frame_sensor_offset_K"), std::string::npos) << text;

  // Restored in a bench whose plant goes on from the same truth.
  Bench r(Config(), b.truth_);
  r.t_us_ = b.t_us_ + 5'000'000;
  r.frame_offset_K = 3.0;
  std::string warning;
  ASSERT_EQ(r.gateway_.RestoreState(text, r.t_us_, &warning), 1) << warning;
  r.Run(60.0, 40.0);
  const PumpSnapshot& after = r.gateway_.pumps()[0]->snapshot();
  EXPECT_EQ(after.sensor_steps, 0U);
  EXPECT_NEAR(after.stepped_offset_K, 3.0, 0.3);
  EXPECT_NEAR(after.sensor_offset_K, s.sensor_offset_K, 0.5);
  EXPECT_NE(after.alarm.active_reasons & kImplausible, 0U);
  EXPECT_NEAR(after.node_degC[0], r.truth_(0), 1.0);

  // Restored against a plant that is not where the state says (started cold): the readings are
  // far from the restored frame, a mismatch the filter follows; the steady readings are no step.
  Bench cold(Config());
  cold.t_us_ = b.t_us_ + 5'000'000;
  cold.frame_offset_K = 3.0;
  ASSERT_EQ(cold.gateway_.RestoreState(text, cold.t_us_, &warning), 1) << warning;
  ASSERT_GT(std::abs(b.truth_(0) - 25.0), 5.0);
  cold.Run(60.0, 40.0);
  EXPECT_EQ(cold.gateway_.pumps()[0]->snapshot().sensor_steps, 0U);

  // A damaged saved offset makes that pump start cold, with a warning.
  std::string damaged = text;
  damaged.replace(damaged.find("frame_sensor_offset_K"), 21, "frame_sensor_offset_K = [ 1.0 ]\nx");
  Bench d(Config());
  d.t_us_ = b.t_us_ + 5'000'000;
  EXPECT_EQ(d.gateway_.RestoreState(damaged, d.t_us_, &warning), 0);
  // Three numbers, but an sd of zero: refused by the pump before anything is restored.
  std::string zero_sd = text;
  zero_sd.replace(zero_sd.find("frame_sensor_offset_K"), 21,
                  "frame_sensor_offset_K = [ 3.0, 0.0, 3.0 ]\nx");
  Bench z(Config());
  z.t_us_ = b.t_us_ + 5'000'000;
  EXPECT_EQ(z.gateway_.RestoreState(zero_sd, z.t_us_, &warning), 0);
}

// What the disturbance-state filter found about the plant outlives a restart: an unmeasured
// ambient 15 K above the one reported, taken as frame-path heat. Restarted from the nodes alone
// with that heat back at its prior, the filter re-learned it through the interior.
TEST(Pipeline, WhatTheFilterFoundAboutThePlantOutlivesARestart) {
  Bench b(Config());
  b.Run(900.0, 40.0);
  b.truth_ambient_degC = 40.0;  // the status frames still say 25 degC
  b.Run(1800.0, 40.0);
  const std::string text = b.gateway_.SaveState();
  ASSERT_NE(text.find("disturbance_x"), std::string::npos);
  // worst_error RESTART_TEXT: the largest |published - truth| over nodes and the first 10 minutes
  // after a restart 5 s later, in a bench whose plant goes on from the same truth.
  auto worst_error = [&](const std::string& saved) {
    Bench r(Config(), b.truth_);
    r.truth_ambient_degC = 40.0;
    r.t_us_ = b.t_us_ + 5'000'000;
    std::string warning;
    EXPECT_EQ(r.gateway_.RestoreState(saved, r.t_us_, &warning), 1) << warning;
    double worst = 0.0;
    for (int k = 0; k < 60; ++k) {
      r.Run(10.0, 40.0);
      const PumpSnapshot& s = r.gateway_.pumps()[0]->snapshot();
      for (std::size_t i = 0; i < s.node_degC.size(); ++i)
        worst = std::max(worst, std::abs(s.node_degC[i] - r.truth_(static_cast<Eigen::Index>(i))));
    }
    return worst;
  };
  // The same file without them (as written before they were saved).
  toml::table root = toml::parse(text);
  for (auto& [name, pump] : *root["pump"].as_table()) {
    pump.as_table()->erase("disturbance_x");
    pump.as_table()->erase("disturbance_s");
  }
  std::ostringstream nodes_only;
  nodes_only << root;
  const double whole = worst_error(text);
  const double priors = worst_error(nodes_only.str());
  std::cout << "largest error in 10 min after a restart: whole state " << whole
            << " K, disturbances at their priors " << priors << " K\n";
  EXPECT_LT(whole, 1.0);
  EXPECT_GT(priors, 2.0 * whole) << "the test no longer shows what the saved disturbances do";

  // Saved by another configuration (another count of states): the nodes alone are restored.
  // Damaged (a negative variance): that pump starts cold.
  auto edited = [&](double first_variance, bool shorter) {
    toml::table t = toml::parse(text);
    for (auto& [name, pump] : *t["pump"].as_table()) {
      if (shorter) pump.as_table()->get_as<toml::array>("disturbance_x")->pop_back();
      toml::array& s = *pump.as_table()->get_as<toml::array>("disturbance_s");
      s.erase(s.begin());
      s.insert(s.begin(), first_variance);
    }
    std::ostringstream out;
    out << t;
    Bench r(Config(), b.truth_);
    r.t_us_ = b.t_us_ + 5'000'000;
    std::string warning;
    return r.gateway_.RestoreState(out.str(), r.t_us_, &warning);
  };
  EXPECT_EQ(edited(1.0, true), 1);
  EXPECT_EQ(edited(-1.0, false), 0);
}

// The losses' stated sd is saved with the filter's state; a damaged value refuses that pump's
// state, a file without it (written before the key) is read as 0.1.
TEST(Pipeline, TheStatedLossesSdIsSavedAndAFileWithoutItIsRead) {
  Bench b(Config("model_losses_sd_rel = 0.3\n"));
  b.Run(60.0, 40.0);
  const std::string text = b.gateway_.SaveState();
  const std::string key = "disturbance_model_losses_sd_rel = ";
  const auto at = text.find(key);
  ASSERT_NE(at, std::string::npos) << text;
  const auto line_end = text.find('\n', at);
  EXPECT_NEAR(std::stod(text.substr(at + key.size(), line_end - at - key.size())), 0.3, 1e-12);
  // restored(TEXT): the pumps restored, and the journal's start line if one was written.
  const auto restored = [&](const std::string& t) {
    Bench r(Config("model_losses_sd_rel = 0.3\n"), b.truth_);
    r.t_us_ = b.t_us_ + 5'000'000;
    std::string warning, start_line;
    const int pumps = r.gateway_.RestoreState(t, r.t_us_, &warning);
    const LogCapture capture([&](LogLevel, std::string_view line) {
      if (line.find("estimate restored") != std::string_view::npos) start_line = line;
    });
    r.Run(5.0, 40.0);
    return std::make_pair(pumps, start_line);
  };
  const auto same = restored(text);
  EXPECT_EQ(same.first, 1);
  EXPECT_EQ(same.second.find("widened"), std::string::npos) << same.second;
  const auto with_value = [&](const std::string& value) {
    std::string t = text;
    return t.replace(at, line_end - at, value.empty() ? "" : key + value);
  };
  const auto older = restored(with_value(""));
  EXPECT_EQ(older.first, 1) << "a file written before the key";
  EXPECT_NE(older.second.find("tmp1: estimate restored from the saved state, its loss scale "
                              "widened to the 0.3 now stated (model_losses_sd_rel; saved with "
                              "0.1)"),
            std::string::npos)
      << older.second;
  for (const char* damaged : {"-0.3", "\"0.3\"", "nan"}) {
    EXPECT_EQ(restored(with_value(damaged)).first, 0) << damaged;
  }
}

// A frame sensor lag the diagnosis named and the filter took is saved with the filter's state
// and read again after a restart, said once in the journal, while the configuration still says
// the lag it was taken over; once the configuration names a lag, that one is read.
TEST(Pipeline, ALagTakenBeforeARestartIsReadAfterItWhileConfigured) {
  const auto config = [](double lag_s) {
    return Config(fmt::format("frame_sensor_lag_s = {}\n", lag_s));
  };
  Bench b(config(30.0));
  b.Run(120.0, 40.0);
  const std::string plain = b.gateway_.SaveState();
  ASSERT_NE(plain.find("disturbance_x"), std::string::npos);
  ASSERT_EQ(plain.find("disturbance_frame_sensor_lag_s"), std::string::npos) << "none taken";
  const auto with_lag = [&](const std::string& value) {
    std::string text = plain;
    text.insert(text.find("disturbance_x"), "disturbance_frame_sensor_lag_s = " + value + "\n");
    return text;
  };
  // restored RESTART_TEXT CONFIGURED_LAG: the bench restarted from it, its journal lines.
  struct Restarted {
    std::unique_ptr<Bench> bench;
    int pumps = 0;
    std::vector<std::string> lines;
  };
  const auto restored = [&](const std::string& text, double configured_s) {
    Restarted r;
    r.bench = std::make_unique<Bench>(config(configured_s), b.truth_);
    r.bench->t_us_ = b.t_us_ + 5'000'000;
    std::string warning;
    r.pumps = r.bench->gateway_.RestoreState(text, r.bench->t_us_, &warning);
    const LogCapture capture([&](LogLevel, std::string_view line) { r.lines.emplace_back(line); });
    r.bench->Run(10.0, 40.0);
    return r;
  };
  const auto is_lag_line = [](const std::string& l) {
    return l.find("sensor read with a lag") != std::string::npos;
  };
  const auto lag_lines = [&](const Restarted& r) {
    return std::count_if(r.lines.begin(), r.lines.end(), is_lag_line);
  };

  const Restarted kept = restored(with_lag("[ 86.0, 30.0 ]"), 30.0);
  ASSERT_EQ(kept.pumps, 1);
  const PumpSnapshot& s = kept.bench->gateway_.pumps()[0]->snapshot();
  EXPECT_EQ(s.frame_sensor_lag_s, 86.0);
  EXPECT_TRUE(s.frame_sensor_lag_restored);
  ASSERT_EQ(lag_lines(kept), 1);
  const std::string line = *std::find_if(kept.lines.begin(), kept.lines.end(), is_lag_line);
  EXPECT_NE(line.find("tmp1: frame sensor read with a lag of 86 s as before the restart"),
            std::string::npos)
      << line;
  EXPECT_NE(line.find("set frame_sensor_lag_s = 86"), std::string::npos) << line;
  const std::string again = kept.bench->gateway_.SaveState();
  EXPECT_NE(again.find("disturbance_frame_sensor_lag_s = [ 86.0, 30.0 ]"), std::string::npos)
      << again;

  // The configuration set to the lag named, or to another: the operator's lag, no line.
  for (const double configured_s : {86.0, 60.0}) {
    const Restarted set = restored(with_lag("[ 86.0, 30.0 ]"), configured_s);
    ASSERT_EQ(set.pumps, 1);
    EXPECT_EQ(set.bench->gateway_.pumps()[0]->snapshot().frame_sensor_lag_s, configured_s);
    EXPECT_FALSE(set.bench->gateway_.pumps()[0]->snapshot().frame_sensor_lag_restored);
    EXPECT_EQ(lag_lines(set), 0);
  }
  // A lag named ten times the configured one (the fit's range), beyond any configurable lag.
  const Restarted far = restored(with_lag("[ 4000.0, 400.0 ]"), 400.0);
  ASSERT_EQ(far.pumps, 1);
  EXPECT_EQ(far.bench->gateway_.pumps()[0]->snapshot().frame_sensor_lag_s, 4000.0);
  // Damaged: one number, a lag of zero, a string. The pump starts afresh.
  for (const std::string bad : {"[ 86.0 ]", "[ 0.0, 30.0 ]", "\"86\""})
    EXPECT_EQ(restored(with_lag(bad), 30.0).pumps, 0) << bad;
}

TEST(Pipeline, NothingIsPublishedAsATemperatureBeforeTheFirstEstimate) {
  Bench b(Config());
  b.Run(0.5, 40.0);  // less than one thermal period
  EXPECT_FALSE(b.gateway_.pumps()[0]->snapshot().initialised);
  const protocol::DbcMessage* temps = b.dbc_.FindMessage("GW_TEMPS_A");
  const auto& codec = b.codec_.message(static_cast<std::size_t>(temps - b.dbc_.messages.data()));
  int seen = 0;
  for (const auto& [t, f] : b.sink.frames) {
    if (f.id != temps->id + 1) continue;
    ++seen;
    std::vector<double> v(codec.signal_count());
    codec.Decode(std::span<const std::uint8_t>(f.data.data(), f.len), v);
    for (double x : v) EXPECT_TRUE(std::isnan(x)) << "a temperature was sent before any estimate";
  }
  EXPECT_GE(seen, 1);
  EXPECT_EQ(b.sink.lcm.count("PUMPTHERM/tmp1/TEMPS"), 0U);
}

TEST(Pipeline, OverheatingTripsLatchesSurvivesARestartAndClearsOnlyFromAConfiguredSource) {
  Bench b(Config(R"(
[pump.alarms.levels]
slot_winding = { warning_degC = 50, trip_degC = 55 }
)"));
  b.Run(300.0, 40.0);
  EXPECT_EQ(b.gateway_.pumps()[0]->snapshot().alarm.level, estimators::AlarmLevel::kNone);
  b.Run(2400.0, 60.0);  // heats past 55 degC
  const auto& s = b.gateway_.pumps()[0]->snapshot();
  ASSERT_GT(b.truth_(3), 57.0);
  EXPECT_EQ(s.alarm.level, estimators::AlarmLevel::kTrip);
  EXPECT_EQ(s.alarm.reason, estimators::AlarmReason::kEstimatedOverTemperature);
  EXPECT_EQ(s.alarm.node, 3);
  EXPECT_TRUE(s.alarm.trip_latched);
  EXPECT_EQ(b.gateway_.counters().trip_latches, 1U);  // the live loop writes the state at once
  // The alarm frame says so, with the model's node index (slot_winding = 3, as GW_NODE_TEMP).
  const protocol::DbcMessage* alarm = b.dbc_.FindMessage("GW_ALARM");
  const auto& codec = b.codec_.message(static_cast<std::size_t>(alarm - b.dbc_.messages.data()));
  protocol::CanFrame last{};
  for (const auto& [t, f] : b.sink.frames) {
    if (f.id == alarm->id + 1) last = f;
  }
  std::vector<double> v(codec.signal_count());
  codec.Decode(std::span<const std::uint8_t>(last.data.data(), last.len), v);
  EXPECT_EQ(v[static_cast<std::size_t>(alarm->FindSignal("AlarmLevel"))], 2.0);
  EXPECT_EQ(v[static_cast<std::size_t>(alarm->FindSignal("AlarmReason"))], 1.0);
  EXPECT_EQ(v[static_cast<std::size_t>(alarm->FindSignal("AlarmNode"))], 3.0);

  // Cool down: still latched. A clear from an unknown source is refused, from "panel" accepted.
  b.Run(3600.0, 0.0);
  ASSERT_LT(b.truth_(3), 45.0);
  EXPECT_EQ(b.gateway_.pumps()[0]->snapshot().alarm.level, estimators::AlarmLevel::kTrip);

  // A restart now (state saved, a new gateway restores it): the trip is still latched although
  // its condition is gone, with the node and the value that raised it, and goes out at once.
  const std::string text = b.gateway_.SaveState();
  EXPECT_NE(text.find("latched_trip_nodes = [ 'slot_winding' ]"), std::string::npos) << text;
  Bench r(Config(R"(
[pump.alarms.levels]
slot_winding = { warning_degC = 50, trip_degC = 55 }
)"));
  r.t_us_ = b.t_us_ + 5'000'000;  // down for 5 s
  std::string warning;
  ASSERT_EQ(r.gateway_.RestoreState(text, r.t_us_, &warning), 1) << warning;
  {
    const auto& before = b.gateway_.pumps()[0]->snapshot().alarm;
    const auto& after = r.gateway_.pumps()[0]->snapshot().alarm;
    EXPECT_EQ(after.level, estimators::AlarmLevel::kTrip);
    EXPECT_TRUE(after.trip_latched);
    EXPECT_EQ(after.reason, estimators::AlarmReason::kEstimatedOverTemperature);
    EXPECT_EQ(after.node, 3);
    EXPECT_DOUBLE_EQ(after.value, before.value);
  }
  r.Run(10.0, 0.0);  // cool telemetry: still latched
  EXPECT_EQ(r.gateway_.pumps()[0]->snapshot().alarm.level, estimators::AlarmLevel::kTrip);
  ASSERT_FALSE(r.sink.frames.empty());
  {
    const protocol::CanFrame* first = nullptr;
    for (const auto& [t, f] : r.sink.frames) {
      if (f.id == alarm->id + 1) {
        first = &f;
        break;
      }
    }
    ASSERT_NE(first, nullptr);
    codec.Decode(std::span<const std::uint8_t>(first->data.data(), first->len), v);
    EXPECT_EQ(v[static_cast<std::size_t>(alarm->FindSignal("AlarmLevel"))], 2.0)
        << "first GW_ALARM after the restart";
  }
  Keyed(r.gateway_);
  const auto after_restart = SignedClear(r.t_us_, 1, "after the restart");
  EXPECT_TRUE(r.gateway_.ClearFromLcm(&after_restart, r.t_us_, r.sink));
  r.Run(10.0, 0.0);
  EXPECT_EQ(r.gateway_.pumps()[0]->snapshot().alarm.level, estimators::AlarmLevel::kNone);
  // A restart whose clock is an hour behind the saved time: the filter starts cold (its age is
  // unknown), the trip latches again all the same and goes out as a trip before any estimate.
  {
    Bench c(Config(R"(
[pump.alarms.levels]
slot_winding = { warning_degC = 50, trip_degC = 55 }
)"));
    c.t_us_ = b.t_us_ - 3'600'000'000LL;
    warning.clear();
    EXPECT_EQ(c.gateway_.RestoreState(text, c.t_us_, &warning), 0);
    EXPECT_NE(warning.find("latched again: tmp1"), std::string::npos) << warning;
    EXPECT_TRUE(c.gateway_.pumps()[0]->snapshot().alarm.trip_latched);
    EXPECT_FALSE(c.gateway_.pumps()[0]->snapshot().initialised);
    c.Run(10.0, 0.0);
    const protocol::CanFrame* first = nullptr;
    for (const auto& [t, f] : c.sink.frames) {
      if (f.id == alarm->id + 1) {
        first = &f;
        break;
      }
    }
    ASSERT_NE(first, nullptr);
    codec.Decode(std::span<const std::uint8_t>(first->data.data(), first->len), v);
    EXPECT_EQ(v[static_cast<std::size_t>(alarm->FindSignal("AlarmLevel"))], 2.0)
        << "first GW_ALARM";
    EXPECT_TRUE(c.gateway_.pumps()[0]->snapshot().alarm.trip_latched);
  }
  // A state without the key (written before trips were saved) restores with none latched; a
  // latched trip on a node the model lacks makes the pump start cold, with a warning.
  std::string old_text = text;
  for (const char* key : {"latched_trip_nodes", "latched_trip_values_degC"}) {
    const std::size_t at = old_text.find(key);
    ASSERT_NE(at, std::string::npos) << key;
    old_text.erase(at, old_text.find('\n', at) + 1 - at);
  }
  Bench o(Config());
  ASSERT_EQ(o.gateway_.RestoreState(old_text, r.t_us_, &warning), 1) << warning << "\n" << old_text;
  EXPECT_FALSE(o.gateway_.pumps()[0]->snapshot().alarm.trip_latched);
  std::string foreign = text;
  foreign.replace(foreign.find("'slot_winding'"), 14, "'no_such_node'");
  Bench f(Config());
  warning.clear();
  EXPECT_EQ(f.gateway_.RestoreState(foreign, r.t_us_, &warning), 0);
  EXPECT_NE(warning.find("tmp1"), std::string::npos) << warning;

  // A source name alone clears nothing, a signed command does.
  EXPECT_FALSE(b.gateway_.Clear("tmp1", "panel", ""));
  Keyed(b.gateway_);
  const auto checked = SignedClear(b.t_us_, 1, "checked the pump");
  EXPECT_TRUE(b.gateway_.ClearFromLcm(&checked, b.t_us_, b.sink));
  b.Run(10.0, 0.0);
  EXPECT_EQ(b.gateway_.pumps()[0]->snapshot().alarm.level, estimators::AlarmLevel::kNone);
  EXPECT_EQ(b.gateway_.counters().clears_refused, 1U);
  EXPECT_EQ(b.gateway_.counters().clears_accepted, 1U);
}

TEST(Pipeline, ForecastSaysWhenTheTripLevelWillBeReached) {
  Bench b(Config(R"(
[pump.alarms.levels]
slot_winding = { warning_degC = 50, trip_degC = 55 }
)"));
  b.Run(60.0, 60.0);
  const auto& s = b.gateway_.pumps()[0]->snapshot();
  ASSERT_TRUE(std::isfinite(s.alarm.time_to_trip_s));
  // Check against the truth: run on and see when the slot winding crosses 55 degC.
  const double forecast_s = s.alarm.time_to_trip_s;
  double crossed_s = -1.0;
  for (int k = 1; k <= 600 && crossed_s < 0; ++k) {
    b.Run(10.0, 60.0);
    if (b.truth_(3) >= 55.0) crossed_s = 10.0 * k;
  }
  ASSERT_GT(crossed_s, 0.0);
  EXPECT_NEAR(forecast_s, crossed_s, 0.1 * crossed_s + 20.0) << "forecast " << forecast_s << " s";
}

// The identifier's drift since the last load change (its status rests on it: held above
// drift_hold_K) survives a restart; before, it was measured afresh from the first block after it.
TEST(Pipeline, IdentifierDriftRoundTripsThroughText) {
  Bench a(Config());
  a.Run(200.0, 30.0);
  a.Run(100.0, 40.0);  // a load change: the identifier anchors its drift there
  Bench b(Config());
  std::string warning;
  ASSERT_EQ(b.gateway_.RestoreState(a.gateway_.SaveState(),
                                    a.gateway_.pumps()[0]->snapshot().time_us, &warning),
            1)
      << warning;
  const auto sa = a.gateway_.pumps()[0]->identifier().Save();
  const auto sb = b.gateway_.pumps()[0]->identifier().Save();
  ASSERT_TRUE(sa.anchor_valid);
  EXPECT_TRUE(sb.anchor_valid);
  EXPECT_EQ(sb.anchor, sa.anchor);
  EXPECT_EQ(sb.drift_V, sa.drift_V);
  EXPECT_EQ(sb.drift_ohm, sa.drift_ohm);
}

TEST(Pipeline, StateRoundTripsThroughText) {
  Bench a(Config());
  a.Run(300.0, 40.0);
  const std::string text = a.gateway_.SaveState();
  Bench b(Config());
  std::string warning;
  EXPECT_EQ(b.gateway_.RestoreState(text, a.gateway_.pumps()[0]->snapshot().time_us, &warning), 1)
      << warning;
  EXPECT_TRUE(warning.empty()) << warning;
  const auto& x = a.gateway_.pumps()[0]->snapshot().node_degC;
  const auto& y = b.gateway_.pumps()[0]->snapshot().node_degC;
  for (std::size_t i = 0; i < x.size(); ++i) EXPECT_NEAR(x[i], y[i], 1e-6);
  // The resistance is published from the restored state before any telemetry or thermal step.
  const auto& ra = a.gateway_.pumps()[0]->snapshot().resistance;
  const auto& rb = b.gateway_.pumps()[0]->snapshot().resistance;
  EXPECT_NE(rb.status, pumptherm::estimators::ResistanceStatus::kInitialising);
  EXPECT_DOUBLE_EQ(rb.resistance_ohm, ra.resistance_ohm);
  // Aged by an hour with the motor at the same load: hotter, not reset to cold.
  Bench c(Config());
  EXPECT_EQ(c.gateway_.RestoreState(
                text, a.gateway_.pumps()[0]->snapshot().time_us + 3'600'000'000LL, &warning),
            1);
  EXPECT_GT(c.gateway_.pumps()[0]->snapshot().node_degC[3], x[3] + 1.0);
  // A state of version 1 (one resistance filter, before the magnet hypotheses): restored, the
  // filter continuing as both hypotheses with the prior probabilities.
  {
    toml::table v1 = toml::parse(text);
    v1.insert_or_assign("version", 1);
    toml::table& p = *v1["pump"]["tmp1"].as_table();
    toml::array x1, p1;
    for (std::size_t i = 0; i < 4; ++i)
      x1.push_back(*(*p["resistance_x"].as_array())[i].value<double>());
    for (std::size_t i = 0; i < 16; ++i)
      p1.push_back(*(*p["resistance_p"].as_array())[i].value<double>());
    p.insert_or_assign("resistance_x", x1);
    p.insert_or_assign("resistance_p", p1);
    p.insert_or_assign("resistance_rejections", 0);
    p.erase("resistance_probability");
    std::ostringstream old;
    old << v1;
    Bench e(Config());
    EXPECT_EQ(
        e.gateway_.RestoreState(old.str(), a.gateway_.pumps()[0]->snapshot().time_us, &warning), 1)
        << warning;
    const auto& re = e.gateway_.pumps()[0]->snapshot().resistance;
    EXPECT_EQ(re.resistance_ohm, x1[0].value<double>().value());
    EXPECT_NEAR(re.steady_magnet_probability,
                pumptherm::estimators::ResistanceIdentifierConfig{}.steady_magnet_prior, 1e-12);
    for (std::size_t i = 0; i < x.size(); ++i)
      EXPECT_NEAR(e.gateway_.pumps()[0]->snapshot().node_degC[i], x[i], 1e-6);
  }
  // A version-2 state written before the excitation moments gained the constant regressor
  // (4 numbers, [iq, w_r]): restored, the constant's row starting empty.
  {
    toml::table v2 = toml::parse(text);
    toml::table& p = *v2["pump"]["tmp1"].as_table();
    const toml::array& m9 = *p["resistance_moments"].as_array();
    ASSERT_EQ(m9.size(), 9U);
    toml::array m4;
    for (const std::size_t i : {0U, 1U, 3U, 4U}) m4.push_back(*m9[i].value<double>());
    p.insert_or_assign("resistance_moments", m4);
    std::ostringstream old;
    old << v2;
    Bench f(Config());
    EXPECT_EQ(
        f.gateway_.RestoreState(old.str(), a.gateway_.pumps()[0]->snapshot().time_us, &warning), 1)
        << warning;
    const auto saved = f.gateway_.pumps()[0]->Save().resistance;
    EXPECT_EQ(saved.moments(0, 1), m4[1].value<double>().value());
    EXPECT_EQ(saved.moments(2, 2), 0.0);
    EXPECT_DOUBLE_EQ(f.gateway_.pumps()[0]->snapshot().resistance.resistance_ohm,
                     ra.resistance_ohm);
  }
  // Damaged or foreign state: ignored with a warning, never a crash.
  Bench d(Config());
  EXPECT_EQ(d.gateway_.RestoreState("version = 1\n[pump.tmp1]\nmodel = \"other\"\n", 0, &warning),
            0);
  EXPECT_NE(warning.find("tmp1"), std::string::npos);
  EXPECT_EQ(d.gateway_.RestoreState("\x01\x02 not toml", 0, &warning), 0);
  EXPECT_NE(warning.find("does not parse"), std::string::npos);
}

TEST(Pipeline, LcmOverMemqCarriesEveryTypeAndAcceptsClearCommands) {
  Bench b(Config());
  b.Run(5.0, 40.0);
  std::vector<std::string> cleared;
  LcmBridge bridge("memq://", "PUMPTHERM",
                   [&](const std::string&, const pumptherm::alarm_clear_t* m) {
                     cleared.push_back(m ? m->pump + "/" + m->key_id : "undecodable");
                   });
  struct Counter {
    std::map<std::string, int> n;
    void On(const lcm::ReceiveBuffer*, const std::string& ch) { ++n[ch]; }
  } counter;
  lcm::LCM listener("memq://");
  // memq is per LCM instance: the bridge's own instance receives what it publishes.
  (void)listener;
  for (const auto& [ch, bytes] : b.sink.lcm) EXPECT_TRUE(bridge.Publish(ch, bytes)) << ch;
  pumptherm::alarm_clear_t clear;
  clear.utime = 0;
  clear.pump = "tmp1";
  clear.gateway = "pumptherm";
  clear.node = "";
  clear.key_id = "panel";
  clear.comment = "test";
  std::vector<std::uint8_t> bytes(static_cast<std::size_t>(clear.getEncodedSize()));
  clear.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
  EXPECT_TRUE(bridge.Publish("PUMPTHERM/tmp1/ALARM_CLEAR", bytes));
  // Bytes that are no alarm_clear_t (another type, an older layout) reach the handler too.
  EXPECT_TRUE(bridge.Publish("PUMPTHERM/tmp1/ALARM_CLEAR", std::vector<std::uint8_t>(12, 0x5A)));
  bridge.Handle();
  ASSERT_EQ(cleared.size(), 2U);
  EXPECT_EQ(cleared[0], "tmp1/panel");
  EXPECT_EQ(cleared[1], "undecodable");
}

TEST(Pipeline, ConfigurationErrorsNameTheKey) {
  auto error_of = [](const std::string& extra) {
    try {
      Gateway g(ParseConfig(Config(extra), "p.toml"));
    } catch (const ConfigError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(error_of("[pump.alarms.levels]\nwinding = { trip_degC = 100 }\n")
                .find("p.toml:25: key 'pump[0].alarms.levels.winding': pump 'tmp1' (model "
                      "saheba2010-improved) has no node 'winding' (its nodes: frame, yoke, teeth, "
                      "slot_winding, end_winding, rotor, shaft; also 'sensor' and "
                      "'winding_resistance')"),
            std::string::npos)
      << error_of("[pump.alarms.levels]\nwinding = { trip_degC = 100 }\n");
  const std::string bad_model = [] {
    try {
      Gateway g(ParseConfig(std::string(R"(
[[can]]
interface = "can0"
[[pump]]
name = "p"
node_id = 1
thermal_model = "no-such-model"
)"),
                            "p.toml"));
    } catch (const ConfigError& e) {
      return std::string(e.what());
    }
    return std::string();
  }();
  EXPECT_NE(
      bad_model.find("p.toml:7: key 'pump[0].thermal_model': 'no-such-model': no such models file"),
      std::string::npos)
      << bad_model;
  // The magnet temperature: a node with capacity, and a motor that states its magnet law.
  const std::string massless = error_of("magnet_node = \"7\"\n");
  EXPECT_NE(massless.find("key 'pump[0].magnet_node': '7' is not a node with heat capacity of "
                          "model saheba2010-improved (its nodes: frame, yoke"),
            std::string::npos)
      << massless;
  // The rotor heat's node: one with capacity.
  const std::string no_rotor = error_of("rotor_node = \"rotr\"\n");
  EXPECT_NE(
      no_rotor.find("key 'pump[0].rotor_node': 'rotr' is not a node with heat capacity of model "
                    "saheba2010-improved"),
      std::string::npos)
      << no_rotor;
  EXPECT_EQ(error_of("rotor_node = \"shaft\"\n"), "");
  const std::string motor_path =
      (std::filesystem::temp_directory_path() / "pipeline_test_no_magnet.toml").string();
  {
    std::ofstream f(motor_path);
    f << "pole_pairs = 1\nrated_speed_rpm = 21000\nflux_Wb = 0.0182\ninductance_H = 0.24e-3\n"
         "[resistance]\nr0_ohm = 0.28\nt0_degC = 27.2\nalpha_per_K = 4.1e-3\n";
  }
  std::string no_law = Config("magnet_node = \"rotor\"\n");
  no_law.replace(no_law.find("motor = \"han2019-tmp\""), 21, "motor = \"" + motor_path + "\"");
  std::string no_law_error;
  try {
    Gateway g(ParseConfig(no_law, "p.toml"));
  } catch (const ConfigError& e) {
    no_law_error = e.what();
  }
  std::filesystem::remove(motor_path);
  EXPECT_NE(no_law_error.find("magnet_node 'rotor' is set but motor"), std::string::npos)
      << no_law_error;
  EXPECT_NE(no_law_error.find("states no [magnet] table"), std::string::npos) << no_law_error;
}

// PUMP_CLEAR repeats within 2 s (a held button) are not acted on but counted; the next one
// after 2 s is (here refused: can0 is no configured clear source).
TEST(Pipeline, ClearFrameRepeatsAreCountedNotDropped) {
  Bench b(Config());
  const std::int64_t t0 = 1'767'225'600'000'000;
  b.Frame("PUMP_CLEAR", t0, {{"ClearTrips", 1.0}});
  b.Frame("PUMP_CLEAR", t0 + 100'000, {{"ClearTrips", 1.0}});
  b.Frame("PUMP_CLEAR", t0 + 200'000, {{"ClearTrips", 1.0}});
  b.Frame("PUMP_CLEAR", t0 + 2'100'000, {{"ClearTrips", 1.0}});
  EXPECT_EQ(b.gateway_.counters().clears_refused, 2U);
  EXPECT_EQ(b.gateway_.counters().clears_rate_limited, 2U);
}

// The CAN alarm frame's reason codes are the daemon's: the DBC's value table names every code
// of estimators::AlarmReason with its log name, and nothing else.
TEST(Pipeline, DbcAlarmReasonTableIsTheDaemonsCodes) {
  const protocol::Dbc dbc = protocol::ParseDbc(
      ReadTextFile(ResolveResource(ResourceKind::kDbc, "pumptherm.dbc")), "pumptherm.dbc");
  const protocol::DbcMessage* alarm = dbc.FindMessage("GW_ALARM");
  ASSERT_NE(alarm, nullptr);
  const int k = alarm->FindSignal("AlarmReason");
  ASSERT_GE(k, 0);
  const auto& table = alarm->signals[static_cast<std::size_t>(k)].value_descriptions;
  EXPECT_EQ(table.size(), estimators::kAlarmReasonCount);
  for (std::size_t code = 0; code < estimators::kAlarmReasonCount; ++code) {
    const auto it = table.find(static_cast<std::int64_t>(code));
    ASSERT_NE(it, table.end()) << "code " << code << " missing from the DBC";
    EXPECT_EQ(it->second, estimators::AlarmReasonName(static_cast<estimators::AlarmReason>(code)))
        << "code " << code;
  }
}

}  // namespace
}  // namespace pumptherm::daemon
