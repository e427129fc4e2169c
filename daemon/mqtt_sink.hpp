#pragma once
/// The MQTT Sparkplug B sink of pumpthermd (docs/mqtt.md): the gateway is an edge node, each
/// pump a device. The loop hands each pump's step to a bounded queue (Offer: no allocation, a
/// short lock, never a wait live); a thread of the sink connects to the broker (libmosquitto,
/// TLS and credentials from files), publishes NBIRTH/DBIRTH on every connection and DDATA per
/// step, answers NCMD Node Control/Rebirth, and reconnects with backoff. The connection's will
/// is the NDEATH of its session (bdSeq). Alarm transitions have their own queue and go with
/// QoS 1; when a queue is full its oldest step is dropped and counted.

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "daemon/config.hpp"
#include "daemon/gateway.hpp"
#include "daemon/mqtt_queue.hpp"
#include "daemon/mqtt_sparkplug.hpp"

struct mosquitto;
struct mosquitto_message;

namespace pumptherm::daemon {

/// Checks the files an [mqtt] table names, as --check-config and the sink's start do: the CA and
/// the client certificate exist, are readable, hold a PEM certificate, and neither group nor
/// others may write them (a CA others can replace lets anyone pose as the broker); the key and
/// the password file as the clear key (SecretKeyFileProblem: this user's or root's, no group or
/// other access, not in a folder others can write), readable, the key a PEM private key, the
/// password file's first line not empty. Throws ConfigError "SOURCE:LINE: key 'mqtt.KEY': ...".
/// Nothing without [mqtt].
void CheckMqttFiles(const DaemonConfig& config);

/// What the sink did, for STATUS= and the summary.
struct MqttCounts {
  bool connected = false;
  std::uint64_t connects = 0;        ///< connections made (each a session: NBIRTH, DBIRTHs)
  std::uint64_t sent = 0;            ///< DDATA published (QoS 0)
  std::uint64_t alarms_sent = 0;     ///< alarm transitions the broker acknowledged (QoS 1)
  std::uint64_t alarms_resent = 0;   ///< alarm transitions sent again on a new connection
  std::uint64_t dropped = 0;         ///< data steps dropped: the queue was full
  std::uint64_t alarms_dropped = 0;  ///< alarm transitions dropped: their queue was full
  std::uint64_t rebirths = 0;        ///< NCMD Node Control/Rebirth answered
};

class MqttSink {
 public:
  /// Checks the configuration's files (the key and password files as the clear key: owned by
  /// this user or root, no group or other access), makes the queues and starts the sink's
  /// thread, which connects in the background. `wait_for_room`: Offer waits for room instead of
  /// dropping (offline runs, which have no timing to keep). Throws std::runtime_error naming
  /// the file or what libmosquitto refused.
  MqttSink(const MqttConfig& config, const std::string& gateway_name, const Gateway& gateway,
           bool wait_for_room);
  ~MqttSink();
  MqttSink(const MqttSink&) = delete;
  MqttSink& operator=(const MqttSink&) = delete;

  /// Queues every pump whose thermal step or alarm is new since the last call. Allocates
  /// nothing; holds the queue's lock for a copy of one step per pump.
  void Offer(const Gateway& gateway);
  /// Sends what is queued (up to `drain_timeout_s`), then NDEATH, and disconnects.
  void Stop(double drain_timeout_s);
  MqttCounts counts() const;
  /// The counts as the health message carries them (no allocation: the loop calls it).
  MqttHealth Health() const;
  /// "mqtt connected to HOST:PORT, N sent, N alarms sent, N dropped, N alarms dropped, N alarms
  /// sent again" for STATUS= and the summary.
  std::string StatusText() const;

 private:
  void Run();
  bool ConnectOnce();
  void Births();
  bool PublishOne();
  /// Hands a message to libmosquitto; `mid_out` (when given) receives its message id.
  bool Publish(const std::string& topic, const std::string& payload, int qos,
               int* mid_out = nullptr);
  static void OnConnect(mosquitto* m, void* self, int rc);
  static void OnDisconnect(mosquitto* m, void* self, int rc);
  static void OnMessage(mosquitto* m, void* self, const mosquitto_message* msg);
  static void OnPublish(mosquitto* m, void* self, int mid);
  /// Turns the client's loop until every QoS 1 message is acknowledged (the broker has read
  /// all before them), at most `timeout_ms`.
  void AwaitAcks(int timeout_ms);

  MqttConfig config_;
  std::string edge_node_id_;
  mqtt::Encoder encoder_;
  std::vector<std::string> topics_data_, topics_birth_;
  std::string topic_nbirth_, topic_ndeath_, topic_ncmd_;
  std::string password_;
  bool wait_for_room_;

  // Shared with the loop, under mutex_.
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  mqtt::StepQueue data_;
  mqtt::AlarmRing alarms_;  ///< alarm transitions, until the broker acknowledged each
  std::uint64_t order_ = 0;
  MqttCounts counts_;
  bool stop_ = false;
  double drain_timeout_s_ = 0.0;

  // The loop's own (Offer).
  std::vector<double> scratch_;
  std::vector<std::int64_t> last_time_us_;
  std::vector<std::uint64_t> last_alarm_changes_;

  // The sink thread's own.
  mosquitto* mosq_ = nullptr;
  std::atomic<bool> connected_{false};
  std::atomic<bool> rebirth_{false};
  std::vector<int> unacked_;  ///< message ids of QoS 1 messages not acknowledged yet
  bool need_birth_ = false;
  mqtt::BdSeq bd_seq_;
  std::vector<std::vector<double>> latest_;  ///< per pump, the newest step taken from a queue
  std::vector<double> step_values_;
  std::thread thread_;
};

}  // namespace pumptherm::daemon
