// Signal mapping: the shipped mapping of pumptherm.dbc resolves; every kind of bad mapping is an
// error naming the source, line, column and key.
#include "protocol/mapping.hpp"

#include <gtest/gtest.h>

#include <string>

#include "tests/protocol/dbc_files.hpp"

namespace pumptherm::protocol {
namespace {

Dbc PumpthermDbc() { return ParseDbc(test::ReadFile(test::PumpthermDbc()), "pumptherm.dbc"); }

constexpr const char* kMinimal = R"(
[inputs]
id_A = { message = "PUMP_FAST_I", signal = "Id_A" }
iq_A = { message = "PUMP_FAST_I", signal = "Iq_A" }
ud_V = { message = "PUMP_FAST_U", signal = "Ud_V" }
uq_V = { message = "PUMP_FAST_U", signal = "Uq_V" }
)";

/// Outputs as a daemon declares them (daemon/published_fields.cpp has the daemon's own): a key,
/// its default message and signal, an old key.
constexpr OutputSpec kOutputs[] = {
    {"winding_resistance_degC", "GW_TEMPS_A", "WindingResistance_degC", "winding_res_temp_degC"},
    {"winding_resistance_sd_K", "GW_IDENT_SD", "WindingResistanceSd_K", "winding_res_sd_K"},
    {"resistance_ohm", "GW_IDENT", "Resistance_ohm", "rs_ohm"},
    {"magnet_flux_degC", "GW_IDENT", "MagnetFlux_degC", "magnet_flux_temp_degC"},
    {"alarm_level", "GW_ALARM", "AlarmLevel", ""},
    {"node_index", "GW_NODE_TEMP", "NodeIndex", ""},
    {"node_temp_degC", "GW_NODE_TEMP", "NodeTemp_degC", ""},
    {"node_sd_K", "GW_NODE_TEMP", "NodeSd_K", ""},
    {"node_count", "GW_NODE_TEMP", "NodeCount", ""},
    {"not_in_this_dbc", "GW_ELSEWHERE", "Nothing", ""},
    {"no_default", "", "", ""},
};

SignalMapping ParseMapping(std::string_view text, std::string_view source, const Dbc& dbc) {
  return protocol::ParseMapping(text, source, dbc, kOutputs);
}

/// Expects ParseMapping(text) to throw a MappingError whose text contains every needle.
void ExpectMappingError(const std::string& text, const Dbc& dbc,
                        std::initializer_list<const char*> needles) {
  try {
    ParseMapping(text, "m.toml", dbc);
    ADD_FAILURE() << "no error for:\n" << text;
  } catch (const MappingError& e) {
    for (const char* n : needles) {
      EXPECT_NE(std::string(e.what()).find(n), std::string::npos) << e.what() << "\nlacks: " << n;
    }
  }
}

TEST(MappingTest, ShippedMappingResolvesEverySignal) {
  const Dbc dbc = PumpthermDbc();
  const auto path = test::SourceDir() / "protocol" / "mapping_pumptherm.toml";
  const SignalMapping m = ParseMapping(test::ReadFile(path), path.string(), dbc);
  EXPECT_EQ(m.node_id_limit, 16u);
  for (std::size_t i = 0; i < kMappingInputCount; ++i) {
    EXPECT_TRUE(m.inputs[i].has_value()) << MappingInputName(static_cast<MappingInput>(i));
  }
  // Every declared default the DBC has is bound; one it lacks and one without a default are not.
  for (const OutputSpec& o : kOutputs) {
    const bool expected = !o.default_message.empty() && o.key != "not_in_this_dbc";
    EXPECT_EQ(m.output(o.key) != nullptr, expected) << o.key;
  }
  EXPECT_EQ(m.node_temperatures.size(), 7u);
  EXPECT_TRUE(m.deprecations.empty()) << m.deprecations.front();
  const SignalRef& id = *m.input(MappingInput::kIdA);
  const DbcMessage& fast = dbc.messages[static_cast<std::size_t>(id.message_index)];
  EXPECT_EQ(fast.name, "PUMP_FAST_I");
  EXPECT_EQ(fast.signals[static_cast<std::size_t>(id.signal_index)].name, "Id_A");
  EXPECT_EQ(id.scale, 1.0);
  const SignalRef& rotor = m.node_temperatures.at("rotor");
  EXPECT_EQ(dbc.messages[static_cast<std::size_t>(rotor.message_index)]
                .signals[static_cast<std::size_t>(rotor.signal_index)]
                .name,
            "Rotor_degC");
  // Pump 3's fast frame: 0x100 + 3.
  EXPECT_EQ(m.CanId(dbc, id.message_index, 3), 0x103u);
  EXPECT_THROW(m.CanId(dbc, id.message_index, 16), std::out_of_range);
}

TEST(MappingTest, ScaleAndOffsetAreRead) {
  const Dbc dbc = PumpthermDbc();
  const SignalMapping m = ParseMapping(std::string(kMinimal) +
                                           "speed_mech_rpm = { message = \"PUMP_STATUS\", signal = "
                                           "\"SpeedMech_rpm\", scale = 0.5, offset = -1 }\n",
                                       "m.toml", dbc);
  EXPECT_EQ(m.input(MappingInput::kSpeedMechRpm)->scale, 0.5);
  EXPECT_EQ(m.input(MappingInput::kSpeedMechRpm)->offset, -1.0);
  EXPECT_FALSE(m.input(MappingInput::kDcLinkV).has_value());
}

TEST(MappingTest, OldOutputKeysStillWorkAndAreReportedDeprecated) {
  const Dbc dbc = PumpthermDbc();
  const std::string kWithSpeed =
      std::string(kMinimal) +
      "speed_mech_rpm = { message = \"PUMP_STATUS\", signal = \"SpeedMech_rpm\" }\n";
  // The names before one name per quantity (docs/daemon.md, "Names").
  const SignalMapping m = ParseMapping(
      kWithSpeed +
          "[outputs]\n"
          "winding_res_temp_degC = { message = \"GW_TEMPS_A\", signal = \"WindingResistance_degC\" "
          "}\n"
          "winding_res_sd_K = { message = \"GW_IDENT_SD\", signal = \"WindingResistanceSd_K\" }\n"
          "magnet_flux_temp_degC = { message = \"GW_IDENT\", signal = \"MagnetFlux_degC\" }\n",
      "m.toml", dbc);
  EXPECT_NE(m.output("winding_resistance_degC"), nullptr);
  EXPECT_NE(m.output("winding_resistance_sd_K"), nullptr);
  EXPECT_NE(m.output("magnet_flux_degC"), nullptr);
  ASSERT_EQ(m.deprecations.size(), 3u);
  std::string all;
  for (const auto& d : m.deprecations) all += d + "\n";
  EXPECT_NE(all.find("m.toml:9:25: key outputs.winding_res_temp_degC is deprecated: it is now "
                     "outputs.winding_resistance_degC\n"),
            std::string::npos)
      << all;
  EXPECT_NE(
      all.find(
          "key outputs.winding_res_sd_K is deprecated: it is now outputs.winding_resistance_sd_K"),
      std::string::npos)
      << all;
  EXPECT_NE(
      all.find(
          "key outputs.magnet_flux_temp_degC is deprecated: it is now outputs.magnet_flux_degC"),
      std::string::npos)
      << all;
  // The current names give no such line; both names at once are an error.
  const SignalMapping now =
      ParseMapping(kWithSpeed +
                       "[outputs]\nwinding_resistance_degC = { message = "
                       "\"GW_TEMPS_A\", signal = \"WindingResistance_degC\" }\n",
                   "m.toml", dbc);
  EXPECT_TRUE(now.deprecations.empty());
  ExpectMappingError(kWithSpeed +
                         "[outputs]\n"
                         "winding_resistance_degC = { message = \"GW_TEMPS_A\", signal = "
                         "\"WindingResistance_degC\" }\n"
                         "winding_res_temp_degC = { message = \"GW_TEMPS_A\", signal = "
                         "\"WindingResistance_degC\" }\n",
                     dbc, {"outputs.winding_resistance_degC is given twice"});
}

TEST(MappingTest, NamesOfProtocolVersion1StillWorkAndAreReportedDeprecated) {
  const Dbc dbc = PumpthermDbc();
  // A mapping written for "pumptherm 1": old input keys, old signal names of pumptherm.dbc.
  const SignalMapping m = ParseMapping(
      std::string(kMinimal) +
          "frame_temp_degC = { message = \"PUMP_STATUS\", signal = \"FrameTemp_degC\" }\n"
          "ambient_temp_degC = { message = \"PUMP_STATUS\", signal = \"AmbientTemp_degC\" }\n"
          "speed_mech_rpm = { message = \"PUMP_STATUS\", signal = \"SpeedMech_rpm\" }\n"
          "[outputs]\n"
          "rs_ohm = { message = \"GW_IDENT\", signal = \"Rs_ohm\" }\n"
          "winding_resistance_degC = { message = \"GW_TEMPS_A\", signal = \"WindingRes_degC\" }\n",
      "m.toml", dbc);
  ASSERT_TRUE(m.input(MappingInput::kFrameSensorDegC).has_value());
  EXPECT_EQ(m.input(MappingInput::kFrameSensorDegC)->signal, "FrameSensor_degC");
  ASSERT_TRUE(m.input(MappingInput::kAmbientDegC).has_value());
  EXPECT_EQ(m.input(MappingInput::kAmbientDegC)->signal, "Ambient_degC");
  ASSERT_NE(m.output("resistance_ohm"), nullptr);
  EXPECT_EQ(m.output("resistance_ohm")->signal, "Resistance_ohm");
  EXPECT_EQ(m.output("winding_resistance_degC")->signal, "WindingResistance_degC");
  std::string all;
  for (const auto& d : m.deprecations) all += d + "\n";
  EXPECT_EQ(m.deprecations.size(), 7u) << all;  // 3 keys, 4 signals
  for (const char* line :
       {"m.toml:7:19: key inputs.frame_temp_degC is deprecated: it is now inputs.frame_sensor_degC",
        "key inputs.ambient_temp_degC is deprecated: it is now inputs.ambient_degC",
        "key outputs.rs_ohm is deprecated: it is now outputs.resistance_ohm",
        "key inputs.frame_temp_degC: signal FrameTemp_degC of PUMP_STATUS is FrameSensor_degC in "
        "pumptherm.dbc (protocol version \"pumptherm 2\" renamed it): read as FrameSensor_degC",
        "signal AmbientTemp_degC of PUMP_STATUS is Ambient_degC",
        "signal Rs_ohm of GW_IDENT is Resistance_ohm",
        "signal WindingRes_degC of GW_TEMPS_A is WindingResistance_degC"}) {
    EXPECT_NE(all.find(line), std::string::npos) << line << "\nin:\n" << all;
  }
  ExpectMappingError(
      std::string(kMinimal) +
          "speed_mech_rpm = { message = \"PUMP_STATUS\", signal = \"SpeedMech_rpm\" }\n"
          "frame_sensor_degC = { message = \"PUMP_STATUS\", signal = \"FrameSensor_degC\" }\n"
          "frame_temp_degC = { message = \"PUMP_STATUS\", signal = \"FrameSensor_degC\" }\n",
      dbc, {"inputs.frame_sensor_degC is given twice"});

  // A site's copy of the DBC of "pumptherm 1": the defaults go to the old names, reported.
  std::string old_text = test::ReadFile(test::PumpthermDbc());
  for (const auto& [now, before] : {std::pair{"WindingResistanceSd_K", "WindingResSd_K"},
                                    std::pair{"WindingResistance_degC", "WindingRes_degC"}}) {
    for (std::size_t at = old_text.find(now); at != std::string::npos; at = old_text.find(now))
      old_text.replace(at, std::string_view(now).size(), before);
  }
  const Dbc old_dbc = ParseDbc(old_text, "site-v1.dbc");
  const SignalMapping on_old = ParseMapping(
      std::string(kMinimal) +
          "speed_mech_rpm = { message = \"PUMP_STATUS\", signal = \"SpeedMech_rpm\" }\n",
      "m.toml", old_dbc);
  ASSERT_NE(on_old.output("winding_resistance_degC"), nullptr);
  EXPECT_EQ(on_old.output("winding_resistance_degC")->signal, "WindingRes_degC");
  EXPECT_EQ(on_old.output("winding_resistance_sd_K")->signal, "WindingResSd_K");
  all.clear();
  for (const auto& d : on_old.deprecations) all += d + "\n";
  EXPECT_NE(all.find("site-v1.dbc: message GW_TEMPS_A has signal WindingRes_degC, the name before "
                     "protocol version \"pumptherm 2\" (now WindingResistance_degC): output "
                     "winding_resistance_degC goes to it"),
            std::string::npos)
      << all;
}

TEST(MappingTest, DefaultsCanBeTurnedOffAndOverridden) {
  const Dbc dbc = PumpthermDbc();
  const std::string with_speed =
      std::string(kMinimal) +
      "speed_mech_rpm = { message = \"PUMP_STATUS\", signal = \"SpeedMech_rpm\" }\n";
  // Only what is named, with `defaults = false`.
  const SignalMapping only = ParseMapping(
      with_speed +
          "[outputs]\ndefaults = false\n"
          "no_default = { message = \"GW_IDENT\", signal = \"Resistance_ohm\", scale = 2 }\n",
      "m.toml", dbc);
  ASSERT_EQ(only.outputs.size(), 1u);
  EXPECT_EQ(only.output("no_default")->signal, "Resistance_ohm");
  EXPECT_EQ(only.output("no_default")->scale, 2.0);
  // A named output wins over its default.
  const SignalMapping over = ParseMapping(
      with_speed +
          "[outputs]\nalarm_level = { message = \"GW_ALARM\", signal = \"AlarmReason\" }\n",
      "m.toml", dbc);
  EXPECT_EQ(over.output("alarm_level")->signal, "AlarmReason");
  EXPECT_NE(over.output("node_index"), nullptr);
  ExpectMappingError(with_speed + "[outputs]\ndefaults = 1\n", dbc,
                     {"outputs.defaults", "expected true or false"});
  // A reader of the inputs alone (no outputs declared) does not read [outputs].
  const SignalMapping inputs =
      protocol::ParseMapping(with_speed + "[outputs]\nwhatever = 3\n", "m.toml", dbc, {});
  EXPECT_TRUE(inputs.outputs.empty());
}

TEST(MappingTest, UnknownMessageOrSignalIsNamed) {
  const Dbc dbc = PumpthermDbc();
  const std::string speed =
      "speed_mech_rpm = { message = \"PUMP_STATUS\", signal = \"SpeedMech_rpm\" }\n";
  ExpectMappingError(std::string(kMinimal) + speed +
                         "dc_link_V = { message = \"PUMP_STATUSS\", signal = \"DcLink_V\" }\n",
                     dbc,
                     {"m.toml:8:", "inputs.dc_link_V.message", "unknown message PUMP_STATUSS"});
  ExpectMappingError(
      std::string(kMinimal) + speed +
          "dc_link_V = { message = \"PUMP_STATUS\", signal = \"DcLink\" }\n",
      dbc,
      {"m.toml:8:", "inputs.dc_link_V.signal", "unknown signal DcLink in message PUMP_STATUS"});
  ExpectMappingError(
      std::string(kMinimal) + speed + "[outputs.nodes]\nrotor = { message = \"GW_TEMPS_B\" }\n",
      dbc, {"outputs.nodes.rotor.signal", "expected the DBC signal name"});
}

TEST(MappingTest, UnknownKeysAndMissingInputsAreErrors) {
  const Dbc dbc = PumpthermDbc();
  const std::string speed =
      "speed_mech_rpm = { message = \"PUMP_STATUS\", signal = \"SpeedMech_rpm\" }\n";
  ExpectMappingError(std::string(kMinimal) + speed +
                         "speed_rpm = { message = \"PUMP_STATUS\", signal = \"SpeedMech_rpm\" }\n",
                     dbc, {"m.toml:8:1", "inputs.speed_rpm", "unknown inputs"});
  ExpectMappingError(
      std::string(kMinimal) + speed +
          "dc_link_V = { message = \"PUMP_STATUS\", signal = \"DcLink_V\", gain = 2 }\n",
      dbc, {"inputs.dc_link_V.gain", "unknown key"});
  ExpectMappingError(std::string("nodeid_limit = 3\n") + kMinimal + speed, dbc,
                     {"m.toml:1:1", "nodeid_limit"});
  ExpectMappingError(kMinimal, dbc,
                     {"missing required input speed_elec_rad_per_s or speed_mech_rpm"});
  ExpectMappingError(
      "[inputs]\nid_A = { message = \"PUMP_FAST_I\", signal = \"Id_A\" }\n", dbc,
      {"missing required input iq_A, ud_V, uq_V, speed_elec_rad_per_s or speed_mech_rpm"});
  ExpectMappingError("[inputs\n", dbc, {"m.toml:1:"});
}

TEST(MappingTest, NodeIdBlocksMustNotOverlapOrOverflow) {
  const Dbc dbc = PumpthermDbc();
  const std::string speed =
      "speed_mech_rpm = { message = \"PUMP_STATUS\", signal = \"SpeedMech_rpm\" }\n";
  // PUMP_FAST_I (0x100) and PUMP_FAST_U (0x110) are 16 apart: 17 pumps would collide.
  ExpectMappingError(std::string("node_id_limit = 17\n") + kMinimal + speed, dbc,
                     {"PUMP_FAST_I", "PUMP_FAST_U", "closer than node_id_limit 17"});
  ExpectMappingError(std::string("node_id_limit = 0\n") + kMinimal + speed, dbc, {"1 to 65536"});
  const Dbc high = ParseDbc(
      "BO_ 2040 F: 8 X\n SG_ I : 0|8@1+ (1,0) [0|0] \"\" X\n SG_ Q : 8|8@1+ (1,0) [0|0] \"\" X\n"
      " SG_ D : 16|8@1+ (1,0) [0|0] \"\" X\n SG_ U : 24|8@1+ (1,0) [0|0] \"\" X\n SG_ W : 32|8@1+ "
      "(1,0) [0|0] \"\" X\n",
      "high.dbc");
  ExpectMappingError(
      "[inputs]\nid_A = { message = \"F\", signal = \"I\" }\niq_A = { message = \"F\", signal = "
      "\"Q\" }\n"
      "ud_V = { message = \"F\", signal = \"D\" }\nuq_V = { message = \"F\", signal = \"U\" }\n"
      "speed_elec_rad_per_s = { message = \"F\", signal = \"W\" }\n",
      high, {"leaves the 11-bit ID range"});
}

}  // namespace
}  // namespace pumptherm::protocol
