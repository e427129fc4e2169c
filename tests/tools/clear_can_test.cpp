// `pumptherm clear-trip` over CAN without a bus: the route the configuration authorises, the
// PUMP_CLEAR frame, and the GW_ALARM level that tells whether the clear took. The live send is
// the same socket code as the daemon's (daemon/can_socket.cpp).
#include "tools/pumptherm/clear_can.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <span>
#include <string>

#include "daemon/published_fields.hpp"
#include "protocol/codec.hpp"
#include "tests/protocol/dbc_files.hpp"
#include "tools/pumptherm/subcommand.hpp"

namespace pumptherm::tools {
namespace {

namespace fs = std::filesystem;

daemon::DaemonConfig ConfigFrom(const std::string& toml) {
  const fs::path dir =
      fs::temp_directory_path() / ("pumptherm_clear_can_" + std::to_string(getpid()));
  fs::create_directories(dir);
  const fs::path file = dir / "d.toml";
  std::ofstream(file) << toml;
  const daemon::DaemonConfig c = daemon::LoadConfig(file.string());
  fs::remove_all(dir);
  return c;
}

constexpr const char* kPumps = R"(
[[can]]
interface = "can0"
[[can]]
interface = "can1"
[[pump]]
name = "tmp1"
node_id = 3
interface = "can0"
[[pump]]
name = "tmp2"
node_id = 4
interface = "can1"
)";

TEST(ClearRouteTest, AutoTakesLcmWhenKeyedElseTheCanInterfaceTheConfigLists) {
  const daemon::DaemonConfig can_only =
      ConfigFrom(std::string("[alarms]\nclear_can_interfaces = [\"can0\"]\n") + kPumps);
  ClearRouteChoice r = ChooseClearRoute(can_only, can_only.pumps[0], "auto");
  EXPECT_EQ(r.route, ClearRoute::kCan);
  EXPECT_EQ(r.interface, "can0");
  // tmp2 is on can1, which the gateway does not accept clears from: no route, and why.
  try {
    ChooseClearRoute(can_only, can_only.pumps[1], "auto");
    ADD_FAILURE() << "tmp2 has no authorised route";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("pump 'tmp2' is on interface 'can1', which is not in "
                                         "alarms.clear_can_interfaces"),
              std::string::npos)
        << e.what();
  }
  EXPECT_THROW(ChooseClearRoute(can_only, can_only.pumps[0], "lcm"), InputError);

  daemon::DaemonConfig keyed = can_only;
  keyed.lcm.url = "memq://";
  keyed.gateway.signing_key_file = "/etc/pumptherm/gateway.key";
  EXPECT_EQ(ChooseClearRoute(keyed, keyed.pumps[0], "auto").route, ClearRoute::kLcm);
  r = ChooseClearRoute(keyed, keyed.pumps[0], "can");
  EXPECT_EQ(r.route, ClearRoute::kCan);
  EXPECT_EQ(r.interface, "can0");
  EXPECT_THROW(ChooseClearRoute(keyed, keyed.pumps[1], "can"), InputError);
}

struct FrameSet {
  protocol::Dbc dbc;
  protocol::SignalMapping mapping;
};

FrameSet Shipped() {
  FrameSet f;
  const auto dir = protocol::test::SourceDir() / "protocol";
  f.dbc = protocol::ParseDbc(protocol::test::ReadFile(dir / "pumptherm.dbc"), "pumptherm.dbc");
  f.mapping = protocol::ParseMapping(protocol::test::ReadFile(dir / "mapping_pumptherm.toml"),
                                     "mapping_pumptherm.toml", f.dbc, daemon::MappingOutputs());
  return f;
}

TEST(ClearFrameTest, PumpClearOfNode3IsId0x703WithClearTripsSet) {
  const FrameSet fs = Shipped();
  const protocol::CanFrame f = EncodeClearFrame(fs.dbc, fs.mapping, 3);
  // protocol/pumptherm.dbc: BO_ 1792 PUMP_CLEAR: 1, ClearTrips bit 0; the ID block is + node ID.
  EXPECT_EQ(f.id, 0x703u);
  EXPECT_FALSE(f.extended);
  ASSERT_EQ(f.len, 1);
  EXPECT_EQ(f.data[0] & 0x01, 0x01);
  // Decoded back with the DBC it is ClearTrips = 1.
  const protocol::DbcMessage& m = *fs.dbc.FindMessage("PUMP_CLEAR");
  std::vector<double> v(m.signals.size());
  ASSERT_EQ(
      protocol::MessageCodec(m).Decode(std::span<const std::uint8_t>(f.data.data(), f.len), v),
      protocol::CodecStatus::kOk);
  EXPECT_EQ(v[0], 1.0);
  EXPECT_THROW(EncodeClearFrame(fs.dbc, fs.mapping, fs.mapping.node_id_limit), InputError);
}

protocol::CanFrame AlarmFrame(const FrameSet& fs, std::uint32_t node_id, double level) {
  const protocol::DbcMessage& m = *fs.dbc.FindMessage("GW_ALARM");
  std::vector<double> v(m.signals.size(), 0.0);
  for (std::size_t i = 0; i < v.size(); ++i) {
    if (m.signals[i].name == "AlarmLevel") v[i] = level;
  }
  protocol::CanFrame f;
  f.id = m.id + node_id;
  f.len = static_cast<std::uint8_t>(m.size_bytes);
  EXPECT_EQ(
      protocol::MessageCodec(m).Encode(v, std::span<std::uint8_t>(f.data.data(), f.len)).status,
      protocol::CodecStatus::kOk);
  return f;
}

TEST(ClearFrameTest, AlarmLevelIsReadFromThisPumpsGwAlarmOnly) {
  const FrameSet fs = Shipped();
  EXPECT_EQ(AlarmLevelOf(fs.dbc, fs.mapping, 3, AlarmFrame(fs, 3, 2)), GatewayAlarmLevel::kTrip);
  EXPECT_EQ(AlarmLevelOf(fs.dbc, fs.mapping, 3, AlarmFrame(fs, 3, 0)), GatewayAlarmLevel::kNormal);
  EXPECT_EQ(AlarmLevelOf(fs.dbc, fs.mapping, 3, AlarmFrame(fs, 4, 2)),
            std::nullopt);  // another pump
  EXPECT_EQ(AlarmLevelOf(fs.dbc, fs.mapping, 3, AlarmFrame(fs, 3, std::nan(""))),
            std::nullopt);  // n/a
  EXPECT_EQ(AlarmLevelOf(fs.dbc, fs.mapping, 3, EncodeClearFrame(fs.dbc, fs.mapping, 3)),
            std::nullopt);
}

TEST(ClearFrameTest, OutcomeSaysWhetherTheTripWentAway) {
  using L = GatewayAlarmLevel;
  auto [code, text] = DescribeCanClear("tmp1", "can0", {L::kTrip, L::kNormal}, 1.2);
  EXPECT_EQ(code, 0);
  EXPECT_NE(text.find("trip before, normal after: trip cleared"), std::string::npos) << text;
  std::tie(code, text) = DescribeCanClear("tmp1", "can0", {L::kNormal, L::kNormal}, 0.1);
  EXPECT_EQ(code, 0);
  EXPECT_NE(text.find("there was no trip to clear"), std::string::npos) << text;
  std::tie(code, text) = DescribeCanClear("tmp1", "can0", {L::kTrip, L::kTrip}, 5);
  EXPECT_EQ(code, 1);
  EXPECT_NE(text.find("still says trip after 5 s"), std::string::npos) << text;
  std::tie(code, text) = DescribeCanClear("tmp1", "can0", {std::nullopt, std::nullopt}, 5);
  EXPECT_EQ(code, 1);
  EXPECT_NE(text.find("no GW_ALARM of this pump came back within 5 s"), std::string::npos) << text;
}

}  // namespace
}  // namespace pumptherm::tools
