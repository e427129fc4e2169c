#include "daemon/live_loop.hpp"

#include <fmt/format.h>
#include <linux/sock_diag.h>
#include <signal.h>
#include <sys/epoll.h>
#include <sys/signalfd.h>
#include <sys/socket.h>
#include <sys/timerfd.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <optional>
#include <string_view>
#include <system_error>
#include <vector>

#include "daemon/can_socket.hpp"
#include "daemon/failure_report.hpp"
#include "daemon/gateway.hpp"
#include "daemon/lcm_bridge.hpp"
#include "daemon/log.hpp"
#include "daemon/mqtt_sink.hpp"
#include "daemon/publish_digest.hpp"
#include "daemon/safety_state.hpp"
#include "daemon/state_store.hpp"
#include "daemon/systemd_notify.hpp"
#include "daemon/unique_fd.hpp"
#include "protocol/lcm/channels.hpp"
#include "pumptherm/alarm_clear_t.hpp"

namespace pumptherm::daemon {
namespace {

constexpr std::uint64_t kSignalTag = 0;
constexpr std::uint64_t kTimerTag = 1;
constexpr std::uint64_t kLcmTag = 2;
constexpr std::uint64_t kFirstSocketTag = 3;
constexpr std::int64_t kReopenPeriodUs = 1000000;  // check and reopen interfaces every second
// The timer is armed for the gateway's next due time (Gateway::NextDueUs) and the loop's own
// periods; this only bounds the sleep.
constexpr std::int64_t kMaxTickUs = 1000000;
constexpr int kRxBudget = 256;  // frames per socket per wake-up (fairness)
// A failure that repeats (LCM sends, state writes) is logged at once, then at most this often.
constexpr std::int64_t kFailureReminderUs = 600'000'000;

[[noreturn]] void ThrowErrno(const char* what) {
  throw std::system_error(errno, std::generic_category(), what);
}

std::int64_t ClockUs(clockid_t clock) {
  timespec ts{};
  clock_gettime(clock, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000 + ts.tv_nsec / 1000;
}

std::int64_t WallMinusMonotonicUs() { return ClockUs(CLOCK_REALTIME) - ClockUs(CLOCK_MONOTONIC); }

}  // namespace

std::int64_t MonotonicStampUs(std::int64_t stamp_wall_us, std::int64_t wall_now_us,
                              std::int64_t mono_now_us, std::int64_t last_mono_us) {
  if (stamp_wall_us <= 0) return std::max(mono_now_us, last_mono_us);  // no kernel stamp
  const std::int64_t mono = stamp_wall_us - (wall_now_us - mono_now_us);
  // A wall clock stepped between the frame's arrival and now moves `mono` by the step: the
  // frame cannot have arrived after now, nor before the frame taken before it.
  return std::max(std::min(mono, mono_now_us), last_mono_us);
}

struct LiveLoop::Impl : OutputSink {
  DaemonConfig config;
  std::string config_path;
  LiveOptions options;
  std::unique_ptr<Gateway> gateway;
  std::unique_ptr<LcmBridge> lcm;
  std::unique_ptr<MqttSink> mqtt;  // the MQTT Sparkplug B sink: [mqtt] only (docs/mqtt.md)
  UniqueFd epoll;
  UniqueFd signal_fd;
  UniqueFd timer_fd;
  std::vector<CanSocket> sockets;          // one per configured interface, same order
  std::vector<std::size_t> gateway_index;  // gateway interface index per socket
  std::vector<int> socket_of_iface;        // gateway interface index -> socket (-1)
  std::vector<std::uint32_t> last_drop_total;
  SystemdNotifier notifier;
  std::int64_t next_status_us = 0;
  std::int64_t next_reopen_us = 0;
  std::int64_t armed_us = 0;  // the time the timer is armed for (ArmTimer)
  std::int64_t next_save_us = 0;
  std::int64_t next_table_us = std::numeric_limits<std::int64_t>::max();  // no table: never
  // The signed digest of what went out on LCM (docs/threat-model.md, "Readers misled").
  PublishDigest digest;
  std::int64_t next_digest_us = std::numeric_limits<std::int64_t>::max();  // none: never
  std::int64_t last_digest_us = std::numeric_limits<std::int64_t>::min() / 2;
  std::string state_path;
  std::string safety_path;  // the safety state (latched trips, clear counters); empty: none
  FailureReport lcm_report{kFailureReminderUs};
  FailureReport save_report{kFailureReminderUs};
  bool stop = false;
  bool hang = false;
  std::uint64_t saved_trip_latches = 0;  // gateway trip_latches at the last state write
  std::int64_t last_frame_mono_us = -1;  // the last frame's stamp on the monotonic clock

  // OutputSink: frames to the pump's socket, LCM to the bridge.
  void SendFrame(std::size_t iface, std::int64_t, const protocol::CanFrame& frame) override {
    if (iface >= socket_of_iface.size() || socket_of_iface[iface] < 0) return;
    const auto i = static_cast<std::size_t>(socket_of_iface[iface]);
    if (!sockets[i].is_open()) return;
    SendCounted(i, gateway->counter().counters(iface), frame);
  }
  /// Sends `frame` on socket `i`, counted on `c`; a link found down is marked so.
  void SendCounted(std::size_t i, InterfaceCounters& c, const protocol::CanFrame& frame) {
    switch (sockets[i].Send(frame)) {
      case TxStatus::kSent:
        ++c.tx_frames;
        break;
      case TxStatus::kDown:
        ++c.tx_dropped;
        MarkUp(i, false);
        break;
      default:
        ++c.tx_dropped;
        break;
    }
  }
  bool PublishLcm(const std::string& channel, std::int64_t,
                  const std::vector<std::uint8_t>& bytes) override {
    if (!lcm) return true;
    const std::int64_t mono = ClockUs(CLOCK_MONOTONIC);
    if (lcm->Publish(channel, bytes)) {
      if (gateway->clear_auth().gateway_key() != nullptr) digest.Add(channel, bytes);
      const FailureReport::Report r = lcm_report.Success(mono);
      if (r.kind == FailureReport::Kind::kRecovered) {
        Log(LogLevel::kNotice, "LCM: sending works again, after {} failed messages in {:.1f} s",
            r.run_failures, r.run_s);
      }
      return true;
    }
    // Counted by the gateway (status line 'lcm ... failed', gateway_health_t); logged sparingly.
    const int err = lcm->last_errno();
    const std::string_view what = err != 0 ? std::strerror(err) : "LCM refused the message";
    const FailureReport::Report r = lcm_report.Failure(mono, what);
    switch (r.kind) {
      case FailureReport::Kind::kFirst:
        Log(LogLevel::kWarning,
            "LCM: cannot send {}: {}; counting failed messages, next report in {} min or when "
            "sending works again",
            channel, what, kFailureReminderUs / 60'000'000);
        break;
      case FailureReport::Kind::kChanged:
      case FailureReport::Kind::kReminder:
        Log(LogLevel::kWarning,
            "LCM: still cannot send: {} ({} failed messages since the last report, {} in {:.0f} s)",
            what, r.failures_since_report, r.run_failures, r.run_s);
        break;
      default:
        break;
    }
    return false;
  }

  void Watch(int fd, std::uint64_t tag) {
    epoll_event ev{};
    ev.events = EPOLLIN;
    ev.data.u64 = tag;
    if (epoll_ctl(epoll.get(), EPOLL_CTL_ADD, fd, &ev) < 0) ThrowErrno("epoll_ctl");
  }

  void MarkUp(std::size_t i, bool up) {
    InterfaceCounters& c = gateway->counter().counters(gateway_index[i]);
    if (c.up == up) return;
    c.up = up;
    c.bus_state = BusState::kUnknown;  // a link that comes back starts over; its error frames tell
    if (up) {
      Log(LogLevel::kNotice, "{}: interface is up again; receiving", sockets[i].name());
    } else {
      Log(LogLevel::kWarning, "{}: interface is down; waiting for it", sockets[i].name());
    }
  }

  /// Opens the socket of one configured interface and logs the receive buffer it got (a warning
  /// when the kernel capped it). Throws as CanSocket::Open.
  static CanSocket OpenSocket(const InterfaceConfig& iface) {
    CanSocket s = CanSocket::Open(iface.name, iface.error_frames, iface.rx_buffer_bytes);
    Log(s.rx_buffer_capped() ? LogLevel::kWarning : LogLevel::kInfo, "{}", s.RxBufferReport());
    return s;
  }

  /// Opens the sockets of `config.interfaces` and maps them to the gateway's interfaces.
  void OpenSockets() {
    sockets.clear();
    gateway_index.clear();
    last_drop_total.clear();
    for (const InterfaceConfig& iface : config.interfaces) {
      sockets.push_back(OpenSocket(iface));
      last_drop_total.push_back(0);
    }
    MapSockets();
    for (std::size_t i = 0; i < sockets.size(); ++i) Watch(sockets[i].fd(), kFirstSocketTag + i);
  }

  void MapSockets() {
    gateway_index.clear();
    socket_of_iface.clear();
    for (std::size_t i = 0; i < config.interfaces.size(); ++i) {
      const std::size_t g = gateway->Interface(config.interfaces[i].name);
      gateway_index.push_back(g);
      if (socket_of_iface.size() <= g) socket_of_iface.resize(g + 1, -1);
      socket_of_iface[g] = static_cast<int>(i);
    }
  }

  /// The MQTT sink of this configuration and gateway (none without [mqtt]); the one before it
  /// sends what it holds (up to 1 s) and its NDEATH first. Throws as MqttSink does.
  void StartMqtt() {
    if (mqtt) mqtt->Stop(1.0);
    mqtt.reset();
    if (!config.mqtt.enabled) return;
    CheckMqttFiles(config);
    mqtt = std::make_unique<MqttSink>(config.mqtt, config.gateway.name, *gateway, false);
    Log(LogLevel::kNotice, "mqtt: publishing to {}:{} as spBv1.0/{}/.../{} ({})", config.mqtt.host,
        config.mqtt.port, config.mqtt.group_id,
        config.mqtt.edge_node_id.empty() ? config.gateway.name : config.mqtt.edge_node_id,
        config.mqtt.ca_file.empty() ? "plain text" : "TLS");
  }

  void StartLcm() {
    lcm.reset();
    if (config.lcm.url.empty()) return;
    lcm =
        std::make_unique<LcmBridge>(config.lcm.url, config.lcm.channel_prefix,
                                    [this](const std::string&, const pumptherm::alarm_clear_t* m) {
                                      // The counter and the latches left are in safety.toml
                                      // before the clear acts; the estimator state follows.
                                      if (gateway->ClearFromLcm(m, ClockUs(CLOCK_REALTIME), *this))
                                        SaveState();
                                    });
    Log(LogLevel::kNotice, "{}", lcm->RestrictToThisHost(config.lcm.receive_interfaces));
    Watch(lcm->fd(), kLcmTag);
  }

  /// The kernel's drop counter of socket `i` (cumulative, 32 bits) is now `drops_total`.
  void CountDrops(std::size_t i, std::uint32_t drops_total) {
    // Wrap-safe; an older value (a frame queued before drops that SyncDrops already counted)
    // changes nothing.
    const auto delta = static_cast<std::int32_t>(drops_total - last_drop_total[i]);
    if (delta <= 0) return;
    gateway->counter().counters(gateway_index[i]).rx_queue_drops +=
        static_cast<std::uint32_t>(delta);
    last_drop_total[i] = drops_total;
  }

  /// Reads socket `i`'s drop counter directly (SO_MEMINFO). A frame carries the counter as it
  /// was when the frame was queued (SO_RXQ_OVFL), so drops after the last queued frame show only
  /// with the next one, and never when the socket is closed first (interface removed while the
  /// queue was full): called before closing and every reopen tick.
  void SyncDrops(std::size_t i) {
    std::uint32_t meminfo[SK_MEMINFO_VARS] = {};
    socklen_t len = sizeof meminfo;
    if (::getsockopt(sockets[i].fd(), SOL_SOCKET, SO_MEMINFO, meminfo, &len) == 0 &&
        len > SK_MEMINFO_DROPS * sizeof(std::uint32_t)) {
      CountDrops(i, meminfo[SK_MEMINFO_DROPS]);
    }
  }

  /// One frame received on socket `i`; `drops_total` is the kernel's drop counter with it.
  void Take(std::size_t i, const protocol::TimedFrame& tf, std::uint32_t drops_total) {
    InterfaceCounters& c = gateway->counter().counters(gateway_index[i]);
    CountDrops(i, drops_total);
    // The kernel reports a link going down before the frames still queued from before: those
    // do not mean it is up again. Only while marked down does a frame cost the ioctl.
    if (!c.up && sockets[i].InterfaceUp()) MarkUp(i, true);
    gateway->OnFrame(gateway_index[i], tf);
  }

  void Drain(std::size_t i) {
    CanSocket& s = sockets[i];
    protocol::TimedFrame tf;
    const std::int64_t mono_now = ClockUs(CLOCK_MONOTONIC);
    const std::int64_t wall_now = ClockUs(CLOCK_REALTIME);
    for (int k = 0; k < kRxBudget && s.is_open(); ++k) {
      std::uint32_t drops_total = last_drop_total[i];
      switch (s.Receive(&tf, &drops_total)) {
        case RxStatus::kFrame:
          tf.time_us = last_frame_mono_us =
              MonotonicStampUs(tf.time_us, wall_now, mono_now, last_frame_mono_us);
          Take(i, tf, drops_total);
          break;
        case RxStatus::kEmpty:
          return;
        case RxStatus::kDown:
          MarkUp(i, false);
          return;
        case RxStatus::kGone: {
          // The removal is reported before the frames still queued on the socket, which were
          // on the bus while the interface existed: take them before closing.
          std::uint64_t late = 0;
          for (;;) {
            drops_total = last_drop_total[i];
            if (s.Receive(&tf, &drops_total) != RxStatus::kFrame) break;
            tf.time_us = last_frame_mono_us =
                MonotonicStampUs(tf.time_us, wall_now, mono_now, last_frame_mono_us);
            Take(i, tf, drops_total);
            ++late;
          }
          SyncDrops(i);
          Log(LogLevel::kWarning,
              "{}: interface was removed ({} frames still queued were taken); will reopen it when "
              "it returns",
              s.name(), late);
          gateway->counter().counters(gateway_index[i]).up = false;
          s.Close();  // closing also removes it from the epoll set
          return;
        }
        case RxStatus::kError:
          Log(LogLevel::kWarning, "{}: receive: {}", s.name(), std::strerror(s.last_errno()));
          return;
      }
    }
  }

  void Reopen() {
    for (std::size_t i = 0; i < sockets.size(); ++i) {
      if (sockets[i].is_open()) {
        MarkUp(i, sockets[i].InterfaceUp());
        SyncDrops(i);
        continue;
      }
      try {
        sockets[i] = OpenSocket(config.interfaces[i]);
        last_drop_total[i] = 0;
        Watch(sockets[i].fd(), kFirstSocketTag + i);
        ++gateway->counter().counters(gateway_index[i]).reopens;
        Log(LogLevel::kNotice, "{}: interface is back; socket reopened", sockets[i].name());
        MarkUp(i, sockets[i].InterfaceUp());
      } catch (const std::system_error&) {
        // Still absent; try again at the next reopen tick.
      }
    }
  }

  void SendHeartbeat(std::int64_t mono_us) {
    while (auto frame = gateway->counter().HeartbeatDue(mono_us)) {
      for (std::size_t i = 0; i < sockets.size(); ++i) {
        if (!sockets[i].is_open()) continue;
        SendCounted(i, gateway->counter().counters(gateway_index[i]), *frame);
      }
    }
  }

  /// Brings the pipeline to now on the monotonic clock (elapsed time: a wall clock set back or
  /// forward neither stops nor skips thermal steps and holds); the wall clock only labels.
  void AdvanceGateway() {
    gateway->SetWallClockOffset(WallMinusMonotonicUs());
    gateway->SetMqttHealth(mqtt ? mqtt->Health() : MqttHealth{});
    gateway->Advance(ClockUs(CLOCK_MONOTONIC), *this);
    if (mqtt) mqtt->Offer(*gateway);
    SaveIfTripLatched();
    DigestWhatWasPublished();
  }

  /// What the pumps just published is signed at once, so that a reader's table shows it signed
  /// rather than pending until the next period's digest; at most ten digests per LCM period
  /// (closer ones wait for the tenth: the timer is armed for it). The period's digest still goes
  /// out when nothing was published (it says the gateway is there).
  void DigestWhatWasPublished() {
    if (!digest.Pending()) return;
    const std::int64_t mono = ClockUs(CLOCK_MONOTONIC);
    const std::int64_t earliest_us = last_digest_us + DigestPeriodUs() / 10;
    if (mono >= earliest_us) {
      PublishDigestNow(mono);
    } else {
      next_digest_us = std::min(next_digest_us, earliest_us);
    }
  }

  /// A trip that latched is written at once (the safety state first, then the estimator
  /// state), not at the next period: a restart (kill -9, watchdog, power loss) right after it
  /// must find it latched.
  void SaveIfTripLatched() {
    const std::uint64_t latches = gateway->counters().trip_latches;
    if (latches == saved_trip_latches) return;
    saved_trip_latches = latches;
    gateway->CommitSafetyState();
    SaveState();
  }

  /// The gateway commits the safety state through this before a clear acts.
  void InstallSafetyCommit() {
    if (safety_path.empty()) return;
    gateway->SetSafetyCommit([this](const std::string& text, std::string* error) {
      try {
        WriteFileAtomically(safety_path, text, 0600, config.gateway.test_safety_write_pause_s);
        return true;
      } catch (const std::exception& e) {
        *error = e.what();
        return false;
      }
    });
  }

  /// Reads safety.toml after the estimator state (whose latches it overrides). `state_found`:
  /// there was a state.toml; `state_before_safety_file`: written by a version without
  /// safety.toml (its latches are the safety state then).
  void RestoreSafetyState(bool state_found, bool state_before_safety_file) {
    const std::int64_t wall = ClockUs(CLOCK_REALTIME);
    const std::int64_t mono = ClockUs(CLOCK_MONOTONIC);
    const std::string tmp = TemporaryPathOf(safety_path);
    if (::unlink(tmp.c_str()) == 0) {
      Log(LogLevel::kNotice,
          "removed {}, an unfinished safety state write (nothing was acted on after it)", tmp);
    }
    std::optional<std::string> text;
    std::string problem;
    try {
      text = ReadFileIfExists(safety_path);
    } catch (const std::exception& e) {
      problem = e.what();
    }
    if (text) {
      if (const auto s = ParseSafetyState(*text, &problem)) {
        gateway->ApplySafetyState(*s, mono);
        std::size_t latched = 0;
        for (const auto& [pump, l] : s->latched) latched += l.size();
        Log(LogLevel::kNotice, "restored the safety state from {}: {} latched trip(s)", safety_path,
            latched);
        return;
      }
      const std::string kept = safety_path + ".damaged";
      ::rename(safety_path.c_str(), kept.c_str());
      problem = fmt::format("{} is damaged: {} (kept as {})", safety_path, problem, kept);
    } else if (problem.empty() && !state_found) {
      Log(LogLevel::kNotice, "no safety state in {}: a first start", safety_path);
      gateway->RefuseClearsSignedUpTo(wall);
      gateway->CommitSafetyState();
      return;
    } else if (problem.empty() && state_before_safety_file) {
      Log(LogLevel::kNotice,
          "no {} yet: the latched trips of {} (an earlier version's) are the safety state",
          safety_path, state_path);
      gateway->RefuseClearsSignedUpTo(wall);
      gateway->CommitSafetyState();
      return;
    } else if (problem.empty()) {
      problem = fmt::format("{} is missing, while {} is there", safety_path, state_path);
    }
    gateway->SafetyStateLost(problem, mono, wall);
    gateway->CommitSafetyState();
  }

  void SaveState() {
    if (state_path.empty()) return;
    const std::int64_t mono = ClockUs(CLOCK_MONOTONIC);
    try {
      WriteFileAtomically(state_path, gateway->SaveState(), 0600,
                          config.gateway.test_state_write_pause_s);
    } catch (const std::exception& e) {
      // Counted (status line 'state ... failed'); the previous file stays as it was.
      const FailureReport::Report r = save_report.Failure(mono, e.what());
      switch (r.kind) {
        case FailureReport::Kind::kFirst:
          Log(LogLevel::kWarning,
              "state not saved: {}; {} keeps the previous state; retrying every {} s, next report "
              "in {} min or when it works again",
              e.what(), state_path, config.gateway.state_save_period_s,
              kFailureReminderUs / 60'000'000);
          break;
        case FailureReport::Kind::kChanged:
        case FailureReport::Kind::kReminder:
          Log(LogLevel::kWarning,
              "state still not saved: {} ({} failed attempts since the last report, {} in {:.0f} "
              "s)",
              e.what(), r.failures_since_report, r.run_failures, r.run_s);
          break;
        default:
          break;
      }
      return;
    }
    const FailureReport::Report r = save_report.Success(mono);
    if (r.kind == FailureReport::Kind::kRecovered) {
      Log(LogLevel::kNotice, "state saved again to {}, after {} failed attempts in {:.0f} s",
          state_path, r.run_failures, r.run_s);
    }
  }

  /// systemd's STATUS=: the gateway's line and the state saving counts.
  std::string Status() const {
    std::string s = gateway->StatusLine();
    if (!state_path.empty())
      s += fmt::format("; state {} saved, {} failed", save_report.successes(),
                       save_report.failures());
    if (mqtt) s += "; " + mqtt->StatusText();
    if (const auto drops = lcm ? lcm->ReceiveDrops() : std::nullopt; drops && *drops > 0)
      s +=
          fmt::format("; lcm {} received dropped (outside the boundary, or a full buffer)", *drops);
    return s;
  }

  void RestoreState() {
    std::string dir = config.gateway.state_directory;
    if (dir.empty()) {
      if (const char* env = std::getenv("STATE_DIRECTORY")) {
        dir = env;
        dir = dir.substr(0, dir.find(':'));
      }
    }
    if (dir.empty()) {
      state_path.clear();
      safety_path.clear();
      // No counters kept: at least a command recorded before this start cannot replay.
      gateway->RefuseClearsSignedUpTo(ClockUs(CLOCK_REALTIME));
      return;
    }
    state_path = dir + "/state.toml";
    safety_path = dir + "/" + kSafetyStateFile;
    InstallSafetyCommit();
    // A temporary left by a write that was cut short (kill -9, power loss): never read, removed.
    const std::string tmp = TemporaryPathOf(state_path);
    if (::unlink(tmp.c_str()) == 0) {
      Log(LogLevel::kNotice,
          "removed {}, the unfinished state write of an earlier run (the saved state is {})", tmp,
          state_path);
    }
    bool found = false;
    bool before_safety_file = false;
    try {
      const auto text = ReadFileIfExists(state_path);
      found = text.has_value();
      if (!text) {
        Log(LogLevel::kNotice, "no saved state in {}; starting cold", state_path);
      } else {
        before_safety_file = WrittenBeforeSafetyFile(*text);
        std::string warning;
        gateway->SetWallClockOffset(WallMinusMonotonicUs());
        const int n = gateway->RestoreState(*text, ClockUs(CLOCK_MONOTONIC), &warning);
        if (!warning.empty()) Log(LogLevel::kWarning, "{}: {}", state_path, warning);
        Log(LogLevel::kNotice, "restored the state of {} pump(s) from {}", n, state_path);
      }
    } catch (const std::exception& e) {
      found = true;
      Log(LogLevel::kWarning, "saved state ignored: {}", e.what());
    }
    RestoreSafetyState(found, before_safety_file);
  }

  void Reload() {
    DaemonConfig next;
    std::unique_ptr<Gateway> next_gateway;
    try {
      next = LoadConfig(config_path);
      next_gateway = std::make_unique<Gateway>(next);
      next_gateway->LoadClearKeys(CredentialsDirectory());
    } catch (const std::exception& e) {
      Log(LogLevel::kError, "reload refused, the running configuration stays: {}", e.what());
      return;
    }
    const bool same_interfaces = [&] {
      if (next.interfaces.size() != config.interfaces.size()) return false;
      for (std::size_t i = 0; i < next.interfaces.size(); ++i) {
        if (next.interfaces[i].name != config.interfaces[i].name ||
            next.interfaces[i].error_frames != config.interfaces[i].error_frames ||
            next.interfaces[i].rx_buffer_bytes != config.interfaces[i].rx_buffer_bytes)
          return false;
      }
      return true;
    }();
    std::vector<CanSocket> new_sockets;
    if (!same_interfaces) {
      try {
        for (const InterfaceConfig& iface : next.interfaces)
          new_sockets.push_back(OpenSocket(iface));
      } catch (const std::exception& e) {
        Log(LogLevel::kError, "reload refused, the running configuration stays: {}", e.what());
        return;
      }
    }
    // Carry every pump's estimate over (pumps of the same name and model).
    std::string warning;
    next_gateway->SetWallClockOffset(WallMinusMonotonicUs());
    const int carried =
        next_gateway->RestoreState(gateway->SaveState(), ClockUs(CLOCK_MONOTONIC), &warning);
    // The latches and the clear counters too: a reload must not reopen a replay.
    next_gateway->ApplySafetyState(gateway->CollectSafetyState(), ClockUs(CLOCK_MONOTONIC));
    const bool lcm_changed =
        next.lcm.url != config.lcm.url || next.lcm.channel_prefix != config.lcm.channel_prefix;
    config = std::move(next);
    gateway = std::move(next_gateway);
    saved_trip_latches = 0;  // the new gateway counts from zero
    InstallSafetyCommit();
    if (!same_interfaces) {
      sockets = std::move(new_sockets);
      last_drop_total.assign(sockets.size(), 0);
      for (std::size_t i = 0; i < sockets.size(); ++i) Watch(sockets[i].fd(), kFirstSocketTag + i);
    }
    MapSockets();
    try {
      StartMqtt();  // the pumps may have changed: new devices, new births
    } catch (const std::exception& e) {
      Log(LogLevel::kError, "MQTT after reload: {}; MQTT is off until the next reload", e.what());
    }
    if (lcm_changed) {
      try {
        StartLcm();
      } catch (const std::exception& e) {
        Log(LogLevel::kError, "LCM after reload: {}; LCM is off until the next reload", e.what());
      }
    }
    Log(LogLevel::kNotice,
        "configuration reloaded from {}: {} pumps ({} carried their estimates over)", config_path,
        gateway->pumps().size(), carried);
  }

  /// The longest time between two digests: the LCM period.
  std::int64_t DigestPeriodUs() const {
    return static_cast<std::int64_t>(config.lcm.period_s * 1e6);
  }

  /// Publishes the signed digest of what went out since the last one (with a gateway key).
  void PublishDigestNow(std::int64_t mono) {
    next_digest_us = mono + DigestPeriodUs();
    last_digest_us = mono;
    const SigningKey* key = gateway->clear_auth().gateway_key();
    if (!lcm || key == nullptr) return;
    const pumptherm::gateway_digest_t d =
        digest.Take(config.gateway.name, config.lcm.channel_prefix, ClockUs(CLOCK_REALTIME), *key);
    std::vector<std::uint8_t> bytes(static_cast<std::size_t>(d.getEncodedSize()));
    d.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
    // Counted and reported with the other LCM sends; not listed in a digest itself.
    (void)lcm->Publish(lcm_channels::GatewayDigestChannelName(config.lcm.channel_prefix), bytes);
  }

  void ArmTimer(std::int64_t mono_now) {
    std::int64_t next = std::min({gateway->NextDueUs(), gateway->counter().NextHeartbeatUs(),
                                  next_status_us, next_reopen_us, next_save_us, next_table_us,
                                  next_digest_us, mono_now + kMaxTickUs});
    const std::int64_t wd = notifier.watchdog_half_period_us();
    if (wd > 0) next = std::min(next, mono_now + wd);
    next = std::max(next, mono_now + 1000);  // at least 1 ms ahead
    itimerspec its{};
    its.it_value.tv_sec = next / 1000000;
    its.it_value.tv_nsec = (next % 1000000) * 1000;
    if (timerfd_settime(timer_fd.get(), TFD_TIMER_ABSTIME, &its, nullptr) < 0)
      ThrowErrno("timerfd_settime");
    armed_us = next;
  }

  void OnTimer() {
    std::uint64_t expirations = 0;
    if (::read(timer_fd.get(), &expirations, sizeof expirations) < 0 && errno != EAGAIN) {
      Log(LogLevel::kWarning, "timerfd read: {}", std::strerror(errno));
    }
    const std::int64_t mono = ClockUs(CLOCK_MONOTONIC);
    AdvanceGateway();
    SendHeartbeat(mono);
    if (mono >= next_reopen_us) {
      Reopen();
      next_reopen_us = mono + kReopenPeriodUs;
    }
    if (mono >= next_status_us) {
      notifier.Status(Status());
      next_status_us = mono + static_cast<std::int64_t>(config.gateway.status_period_s * 1e6);
    }
    if (mono >= next_save_us) {
      SaveState();
      next_save_us = mono + static_cast<std::int64_t>(config.gateway.state_save_period_s * 1e6);
    }
    if (mono >= next_digest_us) PublishDigestNow(mono);
    if (mono >= next_table_us) {
      ShowTable();
      next_table_us = mono + static_cast<std::int64_t>(options.table_period_s * 1e6);
    }
    notifier.KickWatchdog(mono);
    ArmTimer(mono);
  }

  /// The pump table on stderr (--table), redrawn in place on a terminal, with the status line.
  void ShowTable() {
    std::string text = fmt::format("{}\n{}", gateway->StatusLine(), gateway->PumpTable());
    if (::isatty(STDERR_FILENO) == 1) text = "\x1b[H\x1b[2J" + text;
    std::fputs(text.c_str(), stderr);
    std::fflush(stderr);
  }

  void OnSignal() {
    signalfd_siginfo si{};
    while (::read(signal_fd.get(), &si, sizeof si) == static_cast<ssize_t>(sizeof si)) {
      switch (si.ssi_signo) {
        case SIGTERM:
        case SIGINT:
          Log(LogLevel::kNotice, "{} received; stopping",
              si.ssi_signo == SIGTERM ? "SIGTERM" : "SIGINT");
          stop = true;
          break;
        case SIGHUP:
          notifier.Reloading();
          Log(LogLevel::kNotice, "SIGHUP received: reloading {}", config_path);
          Reload();
          notifier.Ready(Status());
          break;
        case SIGUSR1:
          Log(LogLevel::kWarning, "SIGUSR1 with test_hang_switch: the loop hangs now (tests only)");
          hang = true;
          break;
        default:
          break;
      }
    }
  }
};

LiveLoop::LiveLoop(const DaemonConfig& config, std::string config_path, LiveOptions options)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.config = config;
  m.config_path = std::move(config_path);
  m.options = options;
  if (config.interfaces.empty())
    throw ConfigError(config.source + ": no [[can]] interface configured (use -r LOG for a log)");
  m.gateway = std::make_unique<Gateway>(m.config);
  m.gateway->LoadClearKeys(CredentialsDirectory());
  m.epoll = UniqueFd(epoll_create1(EPOLL_CLOEXEC));
  if (!m.epoll.valid()) ThrowErrno("epoll_create1");

  sigset_t mask;
  sigemptyset(&mask);
  sigaddset(&mask, SIGTERM);
  sigaddset(&mask, SIGINT);
  sigaddset(&mask, SIGHUP);
  if (config.gateway.test_hang_switch) sigaddset(&mask, SIGUSR1);
  if (sigprocmask(SIG_BLOCK, &mask, nullptr) < 0) ThrowErrno("sigprocmask");
  m.signal_fd = UniqueFd(signalfd(-1, &mask, SFD_NONBLOCK | SFD_CLOEXEC));
  if (!m.signal_fd.valid()) ThrowErrno("signalfd");
  m.timer_fd = UniqueFd(timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC));
  if (!m.timer_fd.valid()) ThrowErrno("timerfd_create");
  m.Watch(m.signal_fd.get(), kSignalTag);
  m.Watch(m.timer_fd.get(), kTimerTag);
  m.OpenSockets();
  m.StartLcm();
  m.RestoreState();
  m.StartMqtt();
}

LiveLoop::~LiveLoop() = default;

std::string LiveLoop::Summary() const {
  return impl_->Status() + "\n" + impl_->gateway->counter().CountTable();
}

int LiveLoop::Run() {
  Impl& m = *impl_;
  const std::int64_t start = ClockUs(CLOCK_MONOTONIC);
  m.next_status_us = start;
  m.next_reopen_us = start + kReopenPeriodUs;
  m.next_save_us = start + static_cast<std::int64_t>(m.config.gateway.state_save_period_s * 1e6);
  if (m.options.table)
    m.next_table_us = start + static_cast<std::int64_t>(m.options.table_period_s * 1e6);
  if (m.lcm) m.next_digest_us = start + m.DigestPeriodUs();
  std::string names;
  for (const auto& s : m.sockets) names += (names.empty() ? "" : ", ") + s.name();
  Log(LogLevel::kNotice, "listening on {} for {} pump(s){}", names, m.gateway->pumps().size(),
      m.lcm ? ", LCM on " + m.config.lcm.url : "");
  m.notifier.Ready("listening on " + names);
  m.ArmTimer(start);

  epoll_event events[16];
  while (!m.stop) {
    if (m.hang) {
      ::pause();  // tests only: no watchdog kicks from here on
      continue;
    }
    const int n = epoll_wait(m.epoll.get(), events, 16, -1);
    if (n < 0) {
      if (errno == EINTR) continue;
      Log(LogLevel::kError, "epoll_wait: {}", std::strerror(errno));
      return 1;
    }
    bool frames = false;
    for (int k = 0; k < n; ++k) {
      const std::uint64_t tag = events[k].data.u64;
      if (tag == kSignalTag) {
        m.OnSignal();
      } else if (tag == kTimerTag) {
        m.OnTimer();
      } else if (tag == kLcmTag) {
        if (m.lcm) m.lcm->Handle();
      } else {
        const auto i = static_cast<std::size_t>(tag - kFirstSocketTag);
        if (i < m.sockets.size()) {
          m.Drain(i);
          frames = true;
        }
      }
    }
    // Frames, commands and reloads can make work due at once or sooner than the timer.
    const std::int64_t mono = ClockUs(CLOCK_MONOTONIC);
    if (frames || m.gateway->NextDueUs() <= mono) m.AdvanceGateway();
    if (std::min(m.gateway->NextDueUs(), m.next_digest_us) < m.armed_us) m.ArmTimer(mono);
  }
  m.notifier.Stopping();
  m.gateway->FlushClearAudit();
  m.gateway->CommitSafetyState();
  m.SaveState();
  return 0;
}

}  // namespace pumptherm::daemon
