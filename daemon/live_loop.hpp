#pragma once
/// Live mode: one thread, one epoll loop over the CAN sockets, a timerfd for periodic work
/// (heartbeat, systemd status and watchdog, reopening lost interfaces) and a signalfd
/// (SIGTERM/SIGINT stop, SIGHUP). Expected events in the loop are counted, never thrown.

#include <memory>

#include "daemon/config.hpp"
#include "daemon/gateway.hpp"

namespace pumptherm::daemon {

class LiveLoop {
 public:
  /// Opens every configured interface, the epoll, timer and signal descriptors. Throws
  /// std::system_error naming the interface or resource that failed. Blocks SIGTERM, SIGINT
  /// and SIGHUP for the calling thread (they are read from the signalfd).
  LiveLoop(const DaemonConfig& config, Gateway& gateway);
  ~LiveLoop();
  LiveLoop(const LiveLoop&) = delete;
  LiveLoop& operator=(const LiveLoop&) = delete;

  /// Runs until SIGTERM or SIGINT. Returns the process exit code (0 on a clean stop).
  int Run();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace pumptherm::daemon
