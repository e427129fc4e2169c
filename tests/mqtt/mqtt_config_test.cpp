// The [mqtt] table (docs/daemon.md, "[mqtt]") and the sink's bounded queue
// (daemon/mqtt_queue.hpp): defaults, file:line errors, plain text refused off this host; the
// oldest step dropped when full, order and values kept; the alarm ring's bookkeeping (a step
// leaves only on its acknowledgement, in any order; a new connection sends the unacknowledged
// again, in order; a full ring drops the oldest and says so), without a broker.
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

// The alarm ring: pushes 0..n-1, each with one value equal to its order.
mqtt::AlarmRing RingOf(std::size_t capacity, std::uint64_t n) {
  mqtt::AlarmRing r(capacity, 2);
  for (std::uint64_t k = 0; k < n; ++k)
    EXPECT_FALSE(r.Push({0, 1000 + k, k, 0}, std::vector<double>{double(k)}));
  return r;
}

// Sends every waiting step, message ids from `first_mid` up; returns the orders sent.
std::vector<std::uint64_t> SendAll(mqtt::AlarmRing& r, int first_mid) {
  std::vector<std::uint64_t> sent;
  for (int mid = first_mid; r.HasNext(); ++mid) {
    const std::uint64_t order = r.Next().order;
    EXPECT_EQ(r.NextValues().size(), 1U);
    EXPECT_EQ(r.NextValues()[0], double(order));
    sent.push_back(order);
    EXPECT_TRUE(r.MarkSent(order, mid));
  }
  return sent;
}

TEST(MqttAlarmRing, AStepLeavesOnlyWhenAcknowledged) {
  mqtt::AlarmRing r = RingOf(4, 3);
  EXPECT_EQ(SendAll(r, 10), (std::vector<std::uint64_t>{0, 1, 2}));
  EXPECT_EQ(r.size(), 3U);  // accepted by the client, not acknowledged: still there
  EXPECT_EQ(r.in_flight(), 3U);
  EXPECT_FALSE(r.HasNext());
  EXPECT_FALSE(r.Ack(9));  // another message's id
  EXPECT_TRUE(r.Ack(10));
  EXPECT_EQ(r.size(), 2U);
  EXPECT_FALSE(r.Ack(10));  // acknowledged once only
}

TEST(MqttAlarmRing, AcknowledgementsOutOfOrderKeepTheRest) {
  mqtt::AlarmRing r = RingOf(8, 5);
  SendAll(r, 20);  // orders 0..4 as ids 20..24
  EXPECT_TRUE(r.Ack(23));
  EXPECT_TRUE(r.Ack(21));
  EXPECT_EQ(r.size(), 3U);
  EXPECT_EQ(r.in_flight(), 3U);
  // A new connection: the unacknowledged (orders 0, 2, 4) go again, in order, with their values.
  EXPECT_EQ(r.RequeueInFlight(), 3U);
  EXPECT_EQ(SendAll(r, 30), (std::vector<std::uint64_t>{0, 2, 4}));
  EXPECT_FALSE(r.Ack(20));  // the old connection's id of order 0: no longer in flight
  EXPECT_TRUE(r.Ack(32));
  EXPECT_TRUE(r.Ack(30));
  EXPECT_TRUE(r.Ack(31));
  EXPECT_TRUE(r.empty());
}

TEST(MqttAlarmRing, ANewConnectionSendsTheInFlightBeforeTheWaiting) {
  mqtt::AlarmRing r = RingOf(8, 2);
  SendAll(r, 1);
  r.Push({0, 2000, 2, 0}, std::vector<double>{2.0});  // waiting, not sent yet
  EXPECT_EQ(r.in_flight(), 2U);
  EXPECT_EQ(r.RequeueInFlight(), 2U);
  EXPECT_EQ(r.in_flight(), 0U);
  EXPECT_EQ(SendAll(r, 5), (std::vector<std::uint64_t>{0, 1, 2}));
  EXPECT_EQ(r.RequeueInFlight(), 3U);  // lost again before any acknowledgement
  EXPECT_EQ(SendAll(r, 8), (std::vector<std::uint64_t>{0, 1, 2}));
}

TEST(MqttAlarmRing, AFullRingDropsTheOldestUnacknowledged) {
  mqtt::AlarmRing r = RingOf(3, 3);
  SendAll(r, 1);          // orders 0, 1, 2 in flight as 1, 2, 3
  EXPECT_TRUE(r.Ack(1));  // order 0 acknowledged: room for one
  EXPECT_FALSE(r.Push({0, 3, 3, 0}, std::vector<double>{3.0}));
  EXPECT_TRUE(r.Push({0, 4, 4, 0}, std::vector<double>{4.0}));  // drops order 1 (in flight)
  EXPECT_EQ(r.size(), 3U);
  EXPECT_EQ(r.in_flight(), 1U);
  EXPECT_FALSE(r.Ack(2));  // the dropped step's id matches nothing
  EXPECT_EQ(r.RequeueInFlight(), 1U);
  EXPECT_EQ(SendAll(r, 10), (std::vector<std::uint64_t>{2, 3, 4}));
  // Full of waiting steps: the oldest waiting one goes.
  mqtt::AlarmRing w = RingOf(2, 2);
  EXPECT_TRUE(w.Push({0, 5, 5, 0}, std::vector<double>{5.0}));
  EXPECT_EQ(SendAll(w, 1), (std::vector<std::uint64_t>{1, 5}));
}

TEST(MqttAlarmRing, AStepDroppedWhileBeingSentIsNotMarked) {
  mqtt::AlarmRing r = RingOf(2, 2);
  const std::uint64_t order = r.Next().order;                   // taken out to publish...
  EXPECT_TRUE(r.Push({0, 2, 2, 0}, std::vector<double>{2.0}));  // ...and dropped meanwhile
  EXPECT_FALSE(r.MarkSent(order, 7));
  EXPECT_EQ(r.in_flight(), 0U);
  EXPECT_EQ(SendAll(r, 8), (std::vector<std::uint64_t>{1, 2}));
  EXPECT_THROW(r.Push({}, std::vector<double>{1.0, 2.0, 3.0}), std::out_of_range);
  EXPECT_THROW(mqtt::AlarmRing(0, 1), std::invalid_argument);
}

}  // namespace
}  // namespace pumptherm::daemon
