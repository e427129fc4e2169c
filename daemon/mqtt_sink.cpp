// The MQTT Sparkplug B sink (daemon/mqtt_sink.hpp, docs/mqtt.md).
#include "daemon/mqtt_sink.hpp"

#include <fmt/format.h>
#include <mosquitto.h>
#include <sys/stat.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <optional>
#include <sstream>
#include <stdexcept>

#include "daemon/clear_keys.hpp"
#include "daemon/gateway.hpp"
#include "daemon/gateway_detail.hpp"
#include "daemon/log.hpp"

namespace pumptherm::daemon {
namespace {

using mqtt::MessageType;
using Clock = std::chrono::steady_clock;

constexpr auto kBackoffMin = std::chrono::milliseconds(500);
constexpr auto kBackoffMax = std::chrono::seconds(30);
constexpr int kLoopTimeoutMs = 20;
/// Messages published per turn of the sink's loop before it reads the socket again.
constexpr int kBurst = 64;

std::uint64_t WallMs() {
  return static_cast<std::uint64_t>(std::chrono::duration_cast<std::chrono::milliseconds>(
                                        std::chrono::system_clock::now().time_since_epoch())
                                        .count());
}

/// The secret's file: checked as the clear key is, then read (the first line, no newline).
std::string ReadSecretFile(const std::string& path, std::string_view what) {
  if (const std::string problem = SecretKeyFileProblem(path, KeyOwner::kCallerOrRoot);
      !problem.empty())
    throw std::runtime_error(fmt::format("mqtt.{}: {}", what, problem));
  std::ifstream f(path);
  if (!f) throw std::runtime_error(fmt::format("mqtt.{}: cannot read '{}'", what, path));
  std::string line;
  std::getline(f, line);
  return line;
}

/// "" when `path` can be read and holds a line starting with `begin` ("-----BEGIN ..."), else
/// what is wrong.
std::string PemProblem(const std::string& path, std::string_view begin) {
  std::ifstream f(path);
  if (!f) return fmt::format("'{}': cannot be read: {}", path, std::strerror(errno));
  for (std::string line; std::getline(f, line);)
    if (line.rfind(begin, 0) == 0) return "";
  return fmt::format("'{}' holds no '{}' (PEM) block", path, begin);
}

void RequireReadable(const std::string& path, std::string_view what) {
  if (path.empty()) return;
  std::ifstream f(path);
  if (!f) throw std::runtime_error(fmt::format("mqtt.{}: cannot read '{}'", what, path));
}

/// What is wrong with a PEM file others may read (a certificate): "" when nothing is.
std::string PublicPemProblem(const std::string& path, std::string_view begin) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return fmt::format("'{}': {}", path, std::strerror(errno));
  if (!S_ISREG(st.st_mode)) return fmt::format("'{}' is not a regular file", path);
  if ((st.st_mode & (S_IWGRP | S_IWOTH)) != 0)
    return fmt::format("'{}' may be written by its group or others (mode {:04o}): chmod go-w", path,
                       st.st_mode & 07777);
  return PemProblem(path, begin);
}

std::vector<mqtt::Device> Devices(const Gateway& g) {
  std::vector<mqtt::Device> out;
  for (const auto& p : g.pumps())
    out.push_back({p->config().name, mqtt::DeviceMetrics(p->model().StateNames())});
  return out;
}

std::size_t Width(const std::vector<mqtt::Device>& devices) {
  std::size_t w = 0;
  for (const auto& d : devices) w = std::max(w, d.metrics.size());
  return w;
}

}  // namespace

void CheckMqttFiles(const DaemonConfig& config) {
  const MqttConfig& m = config.mqtt;
  if (!m.enabled) return;
  auto fail = [&](std::string_view key, int line, const std::string& problem) {
    if (problem.empty()) return;
    std::string text = fmt::format("{}:{}: key 'mqtt.{}': {}", config.source, line, key, problem);
    if (m.password_file.rfind("/run/credentials/", 0) == 0 && key == "password_file")
      text += " (a LoadCredential= copy exists only while the service runs: check its source)";
    throw ConfigError(text);
  };
  if (!m.ca_file.empty())
    fail("ca_file", m.ca_file_line, PublicPemProblem(m.ca_file, "-----BEGIN CERTIFICATE-----"));
  if (!m.cert_file.empty())
    fail("cert_file", m.cert_file_line,
         PublicPemProblem(m.cert_file, "-----BEGIN CERTIFICATE-----"));
  if (!m.key_file.empty()) {
    fail("key_file", m.key_file_line, SecretKeyFileProblem(m.key_file, KeyOwner::kCallerOrRoot));
    // "-----BEGIN PRIVATE KEY-----", "-----BEGIN RSA PRIVATE KEY-----", "-----BEGIN EC ...".
    std::string problem = PemProblem(m.key_file, "-----BEGIN ");
    if (problem.empty()) {
      std::ifstream f(m.key_file);
      std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
      if (text.find("PRIVATE KEY-----") == std::string::npos)
        problem = fmt::format("'{}' holds no PEM private key", m.key_file);
    }
    fail("key_file", m.key_file_line, problem);
  }
  if (!m.password_file.empty()) {
    fail("password_file", m.password_file_line,
         SecretKeyFileProblem(m.password_file, KeyOwner::kCallerOrRoot));
    std::ifstream f(m.password_file);
    std::string line;
    if (!f)
      fail("password_file", m.password_file_line,
           fmt::format("'{}': cannot be read: {}", m.password_file, std::strerror(errno)));
    std::getline(f, line);
    if (line.empty())
      fail("password_file", m.password_file_line,
           fmt::format("'{}': the first line (the password) is empty", m.password_file));
  }
}

MqttSink::MqttSink(const MqttConfig& config, const std::string& gateway_name,
                   const Gateway& gateway, bool wait_for_room)
    : config_(config),
      edge_node_id_(config.edge_node_id.empty() ? gateway_name : config.edge_node_id),
      encoder_(Devices(gateway)),
      wait_for_room_(wait_for_room),
      data_(config.queue_steps, Width(encoder_.devices())),
      alarms_(config.alarm_queue_steps, Width(encoder_.devices())),
      scratch_(Width(encoder_.devices())),
      last_time_us_(gateway.pumps().size(), std::numeric_limits<std::int64_t>::min()),
      last_alarm_changes_(gateway.pumps().size(), 0),
      step_values_(Width(encoder_.devices())) {
  if (!mqtt::ValidId(edge_node_id_))
    throw std::runtime_error(fmt::format(
        "mqtt: the edge node id '{}' (the gateway's name unless mqtt.edge_node_id is given) "
        "cannot be a Sparkplug id: no '/', '+' or '#'",
        edge_node_id_));
  for (const auto& d : encoder_.devices()) {
    if (!mqtt::ValidId(d.id))
      throw std::runtime_error(
          fmt::format("mqtt: pump name '{}' cannot be a Sparkplug device id", d.id));
    topics_data_.push_back(mqtt::Topic(config_.group_id, MessageType::kDData, edge_node_id_, d.id));
    topics_birth_.push_back(
        mqtt::Topic(config_.group_id, MessageType::kDBirth, edge_node_id_, d.id));
    latest_.emplace_back(d.metrics.size(), kNaN);
  }
  topic_nbirth_ = mqtt::Topic(config_.group_id, MessageType::kNBirth, edge_node_id_);
  topic_ndeath_ = mqtt::Topic(config_.group_id, MessageType::kNDeath, edge_node_id_);
  topic_ncmd_ = mqtt::Topic(config_.group_id, MessageType::kNCmd, edge_node_id_);
  RequireReadable(config_.ca_file, "ca_file");
  RequireReadable(config_.cert_file, "cert_file");
  if (!config_.key_file.empty()) (void)ReadSecretFile(config_.key_file, "key_file");
  if (!config_.password_file.empty())
    password_ = ReadSecretFile(config_.password_file, "password_file");

  mosquitto_lib_init();
  mosq_ = mosquitto_new(edge_node_id_.c_str(), true, this);
  if (mosq_ == nullptr) throw std::runtime_error("mqtt: libmosquitto could not make a client");
  // Publishes only queue; mosquitto_loop (this sink's thread) writes them. Writing inline from
  // mosquitto_publish, libmosquitto 2.0.11 corrupted the stream here (the broker closed the
  // connection: "out of memory") when a QoS 1 acknowledgement came between two publishes.
  mosquitto_threaded_set(mosq_, true);
  mosquitto_int_option(mosq_, MOSQ_OPT_PROTOCOL_VERSION, MQTT_PROTOCOL_V311);
  mosquitto_connect_callback_set(mosq_, &MqttSink::OnConnect);
  mosquitto_disconnect_callback_set(mosq_, &MqttSink::OnDisconnect);
  mosquitto_message_callback_set(mosq_, &MqttSink::OnMessage);
  mosquitto_publish_callback_set(mosq_, &MqttSink::OnPublish);
  if (!config_.ca_file.empty()) {
    const int rc =
        mosquitto_tls_set(mosq_, config_.ca_file.c_str(), nullptr,
                          config_.cert_file.empty() ? nullptr : config_.cert_file.c_str(),
                          config_.key_file.empty() ? nullptr : config_.key_file.c_str(), nullptr);
    if (rc != MOSQ_ERR_SUCCESS)
      throw std::runtime_error(fmt::format("mqtt: TLS setup refused: {}", mosquitto_strerror(rc)));
  }
  if (!config_.username.empty()) {
    const int rc = mosquitto_username_pw_set(mosq_, config_.username.c_str(),
                                             password_.empty() ? nullptr : password_.c_str());
    if (rc != MOSQ_ERR_SUCCESS)
      throw std::runtime_error(fmt::format("mqtt: username refused: {}", mosquitto_strerror(rc)));
  }
  thread_ = std::thread([this] { Run(); });
}

MqttSink::~MqttSink() {
  Stop(0.0);
  if (mosq_ != nullptr) mosquitto_destroy(mosq_);
  mosquitto_lib_cleanup();
}

void MqttSink::Offer(const Gateway& gateway) {
  const auto& pumps = gateway.pumps();
  for (std::size_t i = 0; i < pumps.size(); ++i) {
    const PumpSnapshot& s = pumps[i]->snapshot();
    const bool alarm = s.alarm_changes != last_alarm_changes_[i];
    // As the CSV: a step with an estimate, or an alarm before the first estimate.
    if (s.time_us == last_time_us_[i] && !alarm) continue;
    if (!gateway_detail::AlarmKnown(s)) continue;
    last_time_us_[i] = s.time_us;
    last_alarm_changes_[i] = s.alarm_changes;
    const FieldSource source = gateway.Source(*pumps[i]);
    const std::size_t n = encoder_.devices()[i].metrics.size();
    mqtt::FillDeviceValues(source, std::span<double>(scratch_.data(), n));
    // The step's time to the nearest ms, as the CSV rounds it.
    const double time_ms =
        std::round((static_cast<double>(s.time_us) + source.wall_offset_us) / 1000.0);
    const mqtt::QueuedStep step{static_cast<std::uint32_t>(i),
                                static_cast<std::uint64_t>(std::max(0.0, time_ms)), 0, n};
    std::unique_lock lock(mutex_);
    if (wait_for_room_) {
      // A broker that takes nothing for 30 s: from then on full queues drop, as live.
      const auto room = [&] {
        return stop_ ||
               (alarm ? alarms_.size() < alarms_.capacity() : data_.size() < data_.capacity());
      };
      if (!cv_.wait_for(lock, std::chrono::seconds(30), room)) {
        wait_for_room_ = false;
        Log(LogLevel::kWarning,
            "mqtt: the broker took nothing for 30 s: dropping the oldest steps");
      }
    }
    mqtt::QueuedStep queued = step;
    queued.order = order_++;
    if (alarm) {
      if (alarms_.Push(queued, std::span<const double>(scratch_.data(), n)))
        ++counts_.alarms_dropped;
    } else if (data_.Push(queued, std::span<const double>(scratch_.data(), n))) {
      ++counts_.dropped;
    }
    // No notify: the sink's thread takes the step at its next turn of mosquitto_loop, and only
    // Stop ends its wait between connection attempts (a wake per step would cost the loop a
    // system call and the lock's hand-over while the broker is gone).
  }
}

void MqttSink::Stop(double drain_timeout_s) {
  {
    std::lock_guard lock(mutex_);
    if (!thread_.joinable()) return;
    drain_timeout_s_ = drain_timeout_s;
    stop_ = true;
  }
  cv_.notify_all();
  thread_.join();
}

MqttCounts MqttSink::counts() const {
  std::lock_guard lock(mutex_);
  MqttCounts c = counts_;
  c.connected = connected_;
  return c;
}

MqttHealth MqttSink::Health() const {
  const MqttCounts c = counts();
  return {true, c.connected, c.dropped, c.alarms_dropped};
}

std::string MqttSink::StatusText() const {
  const MqttCounts c = counts();
  return fmt::format(
      "mqtt {} {}:{}, {} sent, {} alarms sent, {} dropped, {} alarms dropped, {} alarms sent again",
      c.connected ? "connected to" : "not connected to", config_.host, config_.port, c.sent,
      c.alarms_sent, c.dropped, c.alarms_dropped, c.alarms_resent);
}

void MqttSink::OnConnect(mosquitto* m, void* self, int rc) {
  auto* sink = static_cast<MqttSink*>(self);
  if (rc != 0) {
    Log(LogLevel::kWarning, "mqtt: {}:{} refused the connection: {}", sink->config_.host,
        sink->config_.port, mosquitto_connack_string(rc));
    return;
  }
  mosquitto_subscribe(m, nullptr, sink->topic_ncmd_.c_str(), 0);
  sink->need_birth_ = true;
  sink->unacked_.clear();  // a new session: what the old one did not acknowledge is not waited for
  {
    // Alarm transitions the old connection did not see acknowledged go again, after the births.
    std::lock_guard lock(sink->mutex_);
    sink->counts_.alarms_resent += sink->alarms_.RequeueInFlight();
  }
  sink->connected_ = true;
}

void MqttSink::OnDisconnect(mosquitto*, void* self, int rc) {
  auto* sink = static_cast<MqttSink*>(self);
  if (sink->connected_ && rc != 0)
    Log(LogLevel::kWarning, "mqtt: connection to {}:{} lost; reconnecting", sink->config_.host,
        sink->config_.port);
  sink->connected_ = false;
}

void MqttSink::OnMessage(mosquitto*, void* self, const mosquitto_message* msg) {
  auto* sink = static_cast<MqttSink*>(self);
  if (msg->topic == nullptr || sink->topic_ncmd_ != msg->topic) return;
  const std::string_view payload(static_cast<const char*>(msg->payload),
                                 static_cast<std::size_t>(std::max(0, msg->payloadlen)));
  if (mqtt::RebirthRequested(payload)) sink->rebirth_ = true;
}

void MqttSink::OnPublish(mosquitto*, void* self, int mid) {
  // QoS 0 messages call this too, once written; QoS 1 once acknowledged (PUBACK).
  auto* sink = static_cast<MqttSink*>(self);
  auto& unacked = sink->unacked_;
  unacked.erase(std::remove(unacked.begin(), unacked.end(), mid), unacked.end());
  {
    std::lock_guard lock(sink->mutex_);
    if (sink->alarms_.Ack(mid)) ++sink->counts_.alarms_sent;
  }
  sink->cv_.notify_all();
}

bool MqttSink::Publish(const std::string& topic, const std::string& payload, int qos,
                       int* mid_out) {
  int mid = 0;
  const int rc = mosquitto_publish(mosq_, &mid, topic.c_str(), static_cast<int>(payload.size()),
                                   payload.data(), qos, false);
  if (rc == MOSQ_ERR_SUCCESS && qos > 0) unacked_.push_back(mid);
  if (mid_out != nullptr) *mid_out = mid;
  return rc == MOSQ_ERR_SUCCESS;
}

void MqttSink::AwaitAcks(int timeout_ms) {
  const auto end = Clock::now() + std::chrono::milliseconds(timeout_ms);
  while (!unacked_.empty() && connected_ && Clock::now() < end) mosquitto_loop(mosq_, 20, 1);
}

bool MqttSink::ConnectOnce() {
  const std::string death = mqtt::Encoder::NodeDeath(bd_seq_.ForNextConnect());
  mosquitto_will_set(mosq_, topic_ndeath_.c_str(), static_cast<int>(death.size()), death.data(), 1,
                     false);
  const int rc = mosquitto_connect(mosq_, config_.host.c_str(), config_.port,
                                   static_cast<int>(config_.keepalive_s));
  // libmosquitto returns success once the CONNECT packet (with this will) is written or queued;
  // on an error no CONNECT went out and its bdSeq is kept for the next attempt.
  if (rc == MOSQ_ERR_SUCCESS) bd_seq_.ConnectSent();
  if (rc != MOSQ_ERR_SUCCESS) {
    Log(LogLevel::kWarning, "mqtt: cannot connect to {}:{}: {}", config_.host, config_.port,
        rc == MOSQ_ERR_ERRNO ? std::strerror(errno) : mosquitto_strerror(rc));
    return false;
  }
  return true;
}

void MqttSink::Births() {
  const std::uint64_t now_ms = WallMs();
  Publish(topic_nbirth_, encoder_.NodeBirth(bd_seq_.Current(), now_ms), 0);
  for (std::size_t d = 0; d < latest_.size(); ++d)
    Publish(topics_birth_[d], encoder_.DeviceBirth(d, latest_[d], now_ms), 0);
  need_birth_ = false;
  std::lock_guard lock(mutex_);
  ++counts_.connects;
}

bool MqttSink::PublishOne() {
  mqtt::QueuedStep step;
  bool alarm = false;
  {
    std::lock_guard lock(mutex_);
    if (data_.empty() && !alarms_.HasNext()) return false;
    // The older of the two fronts first: a pump's steps go out in the order they came.
    alarm = data_.empty() || (alarms_.HasNext() && alarms_.Next().order < data_.Front().order);
    step = alarm ? alarms_.Next() : data_.Front();
    const std::span<const double> front = alarm ? alarms_.NextValues() : data_.FrontValues();
    std::copy(front.begin(), front.end(), step_values_.begin());
  }
  const std::span<const double> values(step_values_.data(), step.count);
  // An alarm transition carries every metric: complete in itself, and not empty when it goes
  // again after a new connection's DBIRTH already carried its values.
  const std::string payload = encoder_.DeviceData(step.device, values, step.time_ms, alarm);
  int mid = 0;
  const bool ok =
      payload.empty() || Publish(topics_data_[step.device], payload, alarm ? 1 : 0, &mid);
  if (!ok && alarm) return false;  // kept: sent after the next connection's births
  std::copy(values.begin(), values.end(), latest_[step.device].begin());
  {
    std::lock_guard lock(mutex_);
    if (alarm) {
      // In flight until its PUBACK (OnPublish); a step that changed nothing has no message and
      // is done at once.
      if (alarms_.MarkSent(step.order, mid) && payload.empty()) alarms_.Ack(mid);
    } else {
      if (!data_.empty() && data_.Front().order == step.order) data_.Pop();
      if (!ok) ++counts_.dropped;  // a data step the broker did not take: not sent again
      if (ok && !payload.empty()) ++counts_.sent;
    }
  }
  cv_.notify_all();
  return true;
}

void MqttSink::Run() {
  auto backoff = std::chrono::duration_cast<Clock::duration>(kBackoffMin);
  auto next_attempt = Clock::now();
  bool socket_open = false;
  std::optional<Clock::time_point> drain_until;
  for (;;) {
    {
      std::unique_lock lock(mutex_);
      if (stop_ && !drain_until)
        drain_until = Clock::now() + std::chrono::milliseconds(
                                         static_cast<std::int64_t>(drain_timeout_s_ * 1000.0));
      const bool empty = data_.empty() && alarms_.empty();
      if (drain_until && (empty || Clock::now() >= *drain_until)) break;
    }
    if (!socket_open) {
      if (Clock::now() < next_attempt) {
        std::unique_lock lock(mutex_);
        cv_.wait_until(lock, next_attempt, [&] { return stop_ && !drain_until; });
        continue;
      }
      socket_open = ConnectOnce();
      if (!socket_open) {
        next_attempt = Clock::now() + backoff;
        backoff = std::min(backoff * 2, std::chrono::duration_cast<Clock::duration>(kBackoffMax));
        continue;
      }
    }
    const int rc = mosquitto_loop(mosq_, kLoopTimeoutMs, 1);
    if (rc != MOSQ_ERR_SUCCESS) {
      connected_ = false;
      socket_open = false;
      mosquitto_disconnect(mosq_);
      next_attempt = Clock::now() + backoff;
      backoff = std::min(backoff * 2, std::chrono::duration_cast<Clock::duration>(kBackoffMax));
      continue;
    }
    if (!connected_) continue;
    backoff = std::chrono::duration_cast<Clock::duration>(kBackoffMin);
    if (rebirth_.exchange(false)) {
      need_birth_ = true;
      std::lock_guard lock(mutex_);
      ++counts_.rebirths;
    }
    if (need_birth_) Births();
    for (int k = 0; k < kBurst && PublishOne(); ++k) {
    }
  }
  if (socket_open && connected_) {
    // A clean end is a death too (spec: an edge node going offline publishes NDEATH).
    // Sent QoS 1 and acknowledged before the DISCONNECT: the broker has then read every message
    // before it (a broker that finds the socket closed while it acknowledges drops the rest).
    Publish(topic_ndeath_, mqtt::Encoder::NodeDeath(bd_seq_.Current()), 1);
    AwaitAcks(2000);
    mosquitto_disconnect(mosq_);
    for (int k = 0; k < 10 && connected_; ++k) mosquitto_loop(mosq_, 20, 1);
  }
}

}  // namespace pumptherm::daemon
