#pragma once
/// Live mode: one thread, one epoll loop over the CAN sockets, a timerfd for periodic work
/// (gateway outputs, heartbeat, systemd status and watchdog, state saving, reopening lost
/// interfaces), a signalfd (SIGTERM/SIGINT stop, SIGHUP reload) and LCM's descriptor.
/// Expected events in the loop are counted, never thrown.

#include <cstdint>
#include <memory>
#include <string>

#include "daemon/config.hpp"

namespace pumptherm::daemon {

/// Options of a live run that are not configuration (command line only).
struct LiveOptions {
  bool table = false;           ///< print the pump table on stderr while running
  double table_period_s = 5.0;  ///< wall-clock seconds between tables
};

/// A kernel receive stamp (SO_TIMESTAMP: CLOCK_REALTIME, us) on CLOCK_MONOTONIC, given both
/// clocks read at about the same moment (`wall_now_us`, `mono_now_us`) and the previous frame's
/// result `last_mono_us` (-1: none). The result lies in [last_mono_us, mono_now_us]: elapsed
/// time never runs backward when the wall clock is set. A stamp of 0 (none) is `mono_now_us`.
std::int64_t MonotonicStampUs(std::int64_t stamp_wall_us, std::int64_t wall_now_us,
                              std::int64_t mono_now_us, std::int64_t last_mono_us);

class LiveLoop {
 public:
  /// Builds the gateway from `config` (loaded from `config_path`, which SIGHUP re-reads), opens
  /// every configured interface, LCM, the epoll, timer and signal descriptors, and restores the
  /// saved state. Throws ConfigError for a configuration that does not fit its files, and
  /// std::system_error / std::runtime_error naming the interface or resource that failed.
  /// Blocks SIGTERM, SIGINT, SIGHUP (and SIGUSR1 with the test hang switch) for this thread.
  LiveLoop(const DaemonConfig& config, std::string config_path, LiveOptions options = {});
  ~LiveLoop();
  LiveLoop(const LiveLoop&) = delete;
  LiveLoop& operator=(const LiveLoop&) = delete;

  /// Runs until SIGTERM or SIGINT. Returns the process exit code (0 on a clean stop).
  int Run();

  /// The final summary (status line and per-ID counts), for stdout at exit.
  std::string Summary() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace pumptherm::daemon
