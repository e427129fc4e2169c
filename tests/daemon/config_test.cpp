#include "daemon/config.hpp"

#include <gtest/gtest.h>

#include "daemon/pump.hpp"

namespace pumptherm::daemon {
namespace {

std::string ErrorOf(const std::string& text) {
  try {
    ParseConfig(text, "p.toml");
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(Config, ParsesGatewayAndInterfaces) {
  const auto c = ParseConfig(R"(
[gateway]
name = "bench"
heartbeat_id = 0x7F1
heartbeat_period_s = 0.5
status_period_s = 1

[[can]]
interface = "vcan0"

[[can]]
interface = "can1"
error_frames = true
rx_buffer_bytes = 4194304
)",
                             "p.toml");
  EXPECT_EQ(c.gateway.name, "bench");
  EXPECT_EQ(c.gateway.heartbeat_id, 0x7F1U);
  EXPECT_DOUBLE_EQ(c.gateway.heartbeat_period_s, 0.5);
  EXPECT_DOUBLE_EQ(c.gateway.status_period_s, 1.0);
  ASSERT_EQ(c.interfaces.size(), 2U);
  EXPECT_EQ(c.interfaces[0].name, "vcan0");
  EXPECT_FALSE(c.interfaces[0].error_frames);
  EXPECT_TRUE(c.interfaces[1].error_frames);
  EXPECT_EQ(c.interfaces[0].rx_buffer_bytes, kDefaultRxBufferBytes);
  EXPECT_EQ(c.interfaces[1].rx_buffer_bytes, 4194304);
}

TEST(Config, ReceiveBufferRange) {
  EXPECT_EQ(kDefaultRxBufferBytes, 1048576);  // docs/daemon.md and pumpthermd.toml(5) say so
  EXPECT_EQ(ParseConfig("[[can]]\ninterface = \"can0\"\nrx_buffer_bytes = 0\n", "p.toml")
                .interfaces[0]
                .rx_buffer_bytes,
            0);
  EXPECT_EQ(ParseConfig("[[can]]\ninterface = \"can0\"\nrx_buffer_bytes = 4096\n", "p.toml")
                .interfaces[0]
                .rx_buffer_bytes,
            4096);
  EXPECT_EQ(ParseConfig("[[can]]\ninterface = \"can0\"\nrx_buffer_bytes = 268435456\n", "p.toml")
                .interfaces[0]
                .rx_buffer_bytes,
            268435456);
  EXPECT_EQ(
      ErrorOf("[[can]]\ninterface = \"can0\"\nrx_buffer_bytes = 4095\n"),
      "p.toml:3: key 'can[0].rx_buffer_bytes': 4095 is below 4096 (0 keeps the kernel's default)");
  EXPECT_EQ(ErrorOf("[[can]]\ninterface = \"can0\"\nrx_buffer_bytes = 268435457\n"),
            "p.toml:3: key 'can[0].rx_buffer_bytes': 268435457 is outside [0, 268435456]");
  EXPECT_EQ(ErrorOf("[[can]]\ninterface = \"can0\"\nrx_buffer_bytes = -1\n"),
            "p.toml:3: key 'can[0].rx_buffer_bytes': -1 is outside [0, 268435456]");
  EXPECT_EQ(ErrorOf("[[can]]\ninterface = \"can0\"\nrx_buffer_bytes = 1.5e6\n"),
            "p.toml:3: key 'can[0].rx_buffer_bytes': expected an integer");
}

TEST(Config, ModelLossesSdReachesTheLossScaleAndIsRanged) {
  const std::string pump = "[[pump]]\nname = \"p\"\nnode_id = 1\n";
  const auto c = ParseConfig(pump + "model_losses_sd_rel = 0.3\n", "p.toml");
  const estimators::PumpEstimatorConfig e = EstimatorConfig(c.pumps[0], 1.0);
  EXPECT_DOUBLE_EQ(e.disturbance.loss_scale_initial_sd, 0.3);
  EXPECT_DOUBLE_EQ(e.disturbance.loss_scale_max_sd, 0.3);
  // The default: a model checked against this pump; the stationary sd stays the filter's own.
  const estimators::PumpEstimatorConfig d =
      EstimatorConfig(ParseConfig(pump, "p.toml").pumps[0], 1.0);
  EXPECT_DOUBLE_EQ(d.disturbance.loss_scale_initial_sd, 0.1);
  EXPECT_DOUBLE_EQ(d.disturbance.loss_scale_max_sd,
                   estimators::DisturbanceSensorConfig{}.loss_scale_max_sd);
  EXPECT_DOUBLE_EQ(
      EstimatorConfig(ParseConfig(pump + "model_losses_sd_rel = 0.6\n", "p.toml").pumps[0], 1.0)
          .disturbance.loss_scale_max_sd,
      0.6);
  EXPECT_EQ(ErrorOf(pump + "model_losses_sd_rel = 0\n"),
            "p.toml:4: key 'pump[0].model_losses_sd_rel': 0 is outside [0.01, 1]");
  EXPECT_EQ(ErrorOf(pump + "model_losses_sd_rel = 1.5\n"),
            "p.toml:4: key 'pump[0].model_losses_sd_rel': 1.5 is outside [0.01, 1]");
}

TEST(Config, EmptyFileGivesDefaults) {
  const auto c = ParseConfig("", "p.toml");
  EXPECT_EQ(c.gateway.heartbeat_id, 0x7F0U);
  EXPECT_TRUE(c.interfaces.empty());
}

TEST(Config, ErrorsNameFileLineAndKey) {
  EXPECT_EQ(ErrorOf("[gateway]\nheartbeat_period_s = \"1\"\n"),
            "p.toml:2: key 'gateway.heartbeat_period_s': expected a number");
  EXPECT_EQ(ErrorOf("[gateway]\n\nheartbeat_id = 0x800\n"),
            "p.toml:3: key 'gateway.heartbeat_id': 2048 is outside [0, 2047]");
  EXPECT_EQ(ErrorOf("[gateway]\nheartbeat_periods = 1\n"),
            "p.toml:2: key 'gateway.heartbeat_periods': unknown key");
  EXPECT_EQ(ErrorOf("[[can]]\nerror_frames = true\n"),
            "p.toml:1: key 'can[0].interface': missing (required)");
  EXPECT_EQ(ErrorOf("[[can]]\ninterface = \"vcan0\"\n[[can]]\ninterface = \"vcan0\"\n"),
            "p.toml:4: key 'can[1].interface': 'vcan0' is listed twice");
  EXPECT_EQ(ErrorOf("[[can]]\ninterface = \"a/b\"\n"),
            "p.toml:2: key 'can[0].interface': 'a/b' is not an interface name (1 to 15 "
            "characters, no '/' or space)");
  EXPECT_EQ(ErrorOf("[gateway]\nstatus_period_s = nan\n"),
            "p.toml:2: key 'gateway.status_period_s': expected a finite number");
  EXPECT_EQ(ErrorOf("[gateway\n"),
            "p.toml:1:9: Error while parsing table header: expected ']', saw '\\n'");
  EXPECT_EQ(ErrorOf("gateway = 3\n"), "p.toml:1: key 'gateway': expected a table [gateway]");
}

TEST(Config, UnreadableFileIsAConfigError) {
  try {
    LoadConfig("/nonexistent/pumpthermd.toml");
    FAIL() << "no error";
  } catch (const ConfigError& e) {
    EXPECT_EQ(std::string(e.what()),
              "/nonexistent/pumpthermd.toml: cannot open: No such file or directory");
  }
}

}  // namespace
}  // namespace pumptherm::daemon
