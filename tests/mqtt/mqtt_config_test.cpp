// The [mqtt] table (docs/daemon.md, "[mqtt]") and the sink's bounded queue
// (daemon/mqtt_queue.hpp): defaults, file:line errors, plain text refused off this host; the
// oldest step dropped when full, order and values kept.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "daemon/config.hpp"
#include "daemon/mqtt_queue.hpp"

namespace pumptherm::daemon {
namespace {

std::string ErrorOf(const std::string& text) {
  try {
    ParseConfig(text, "/etc/p/p.toml");
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(MqttConfig, OffWithoutTheTable) {
  const DaemonConfig c = ParseConfig("[gateway]\nname = \"gw\"\n", "p.toml");
  EXPECT_FALSE(c.mqtt.enabled);
}

TEST(MqttConfig, DefaultsAndPathsFromTheConfigsFolder) {
  const DaemonConfig c = ParseConfig(R"([mqtt]
host = "broker.plant"
ca_file = "ca.pem"
cert_file = "/etc/ssl/gw.pem"
key_file = "gw.key"
username = "gw7"
password_file = "/run/credentials/pumpthermd.service/mqtt-password"
)",
                                     "/etc/p/p.toml");
  EXPECT_TRUE(c.mqtt.enabled);
  EXPECT_EQ(c.mqtt.host, "broker.plant");
  EXPECT_EQ(c.mqtt.port, 8883);  // TLS
  EXPECT_EQ(c.mqtt.group_id, "pumptherm");
  EXPECT_EQ(c.mqtt.edge_node_id, "");  // the gateway's name
  EXPECT_EQ(c.mqtt.ca_file, "/etc/p/ca.pem");
  EXPECT_EQ(c.mqtt.cert_file, "/etc/ssl/gw.pem");
  EXPECT_EQ(c.mqtt.key_file, "/etc/p/gw.key");
  EXPECT_EQ(c.mqtt.password_file, "/run/credentials/pumpthermd.service/mqtt-password");
  EXPECT_EQ(c.mqtt.queue_steps, 256U);
  EXPECT_EQ(c.mqtt.alarm_queue_steps, 1024U);
  EXPECT_EQ(c.mqtt.line, 1);
}

TEST(MqttConfig, LocalPlainTextIsAllowedElsewhereOnlyWhenSaid) {
  EXPECT_EQ(ParseConfig("[mqtt]\nhost = \"127.0.0.1\"\n", "p.toml").mqtt.port, 1883);
  EXPECT_EQ(ErrorOf("[mqtt]\nhost = \"localhost\"\n"), "");
  const std::string e = ErrorOf("\n[mqtt]\nhost = \"10.0.0.5\"\n");
  EXPECT_NE(e.find("/etc/p/p.toml:3: key 'mqtt.host'"), std::string::npos) << e;
  EXPECT_NE(e.find("allow_plaintext = true"), std::string::npos) << e;
  EXPECT_EQ(ErrorOf("[mqtt]\nhost = \"10.0.0.5\"\nallow_plaintext = true\n"), "");
}

TEST(MqttConfig, BadKeysNameFileLineAndKey) {
  auto has = [](const std::string& text, const std::string& want) {
    const std::string e = ErrorOf(text);
    EXPECT_NE(e.find(want), std::string::npos) << "error: '" << e << "', want '" << want << "'";
  };
  has("[mqtt]\nport = 1883\n", "key 'mqtt.host': missing");
  has("[mqtt]\nhost = \"h\"\nallow_plaintext = true\nport = 70000\n", ":4: key 'mqtt.port'");
  has("[mqtt]\nhost = \"localhost\"\ngroup_id = \"a/b\"\n", ":3: key 'mqtt.group_id'");
  has("[mqtt]\nhost = \"localhost\"\nedge_node_id = \"gw#\"\n", ":3: key 'mqtt.edge_node_id'");
  has("[mqtt]\nhost = \"localhost\"\nca_file = \"ca\"\ncert_file = \"c\"\n", "key 'mqtt.key_file'");
  has("[mqtt]\nhost = \"localhost\"\ncert_file = \"c\"\nkey_file = \"k\"\n", "key 'mqtt.ca_file'");
  has("[mqtt]\nhost = \"localhost\"\npassword_file = \"p\"\n", "key 'mqtt.username'");
  has("[mqtt]\nhost = \"localhost\"\nhots = \"x\"\n", ":3: key 'mqtt.hots': unknown key");
  has("[mqtt]\nhost = \"localhost\"\nqueue_steps = 0\n", ":3: key 'mqtt.queue_steps'");
}

TEST(MqttQueue, KeepsOrderAndDropsTheOldestWhenFull) {
  mqtt::StepQueue q(3, 2);
  const std::vector<double> v{1.0, 2.0};
  for (std::uint64_t k = 0; k < 3; ++k)
    EXPECT_FALSE(q.Push({0, 100 + k, k, 0}, std::vector<double>{double(k), double(k) + 0.5}));
  EXPECT_EQ(q.size(), 3U);
  EXPECT_TRUE(q.Push({1, 103, 3, 0}, std::vector<double>{3.0}));  // drops order 0
  EXPECT_EQ(q.size(), 3U);
  std::vector<std::uint64_t> orders;
  while (!q.empty()) {
    orders.push_back(q.Front().order);
    const auto values = q.FrontValues();
    if (q.Front().order == 3) {
      ASSERT_EQ(values.size(), 1U);
      EXPECT_EQ(values[0], 3.0);
      EXPECT_EQ(q.Front().device, 1U);
    } else {
      ASSERT_EQ(values.size(), 2U);
      EXPECT_EQ(values[1], static_cast<double>(q.Front().order) + 0.5);
    }
    q.Pop();
  }
  EXPECT_EQ(orders, (std::vector<std::uint64_t>{1, 2, 3}));
  EXPECT_THROW(q.Push({}, std::vector<double>{1.0, 2.0, 3.0}), std::out_of_range);
  EXPECT_THROW(mqtt::StepQueue(0, 1), std::invalid_argument);
}

}  // namespace
}  // namespace pumptherm::daemon
