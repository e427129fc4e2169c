#pragma once
/// The daemon's side of the systemd notify protocol (sd_notify(3)): READY=1 once the sockets
/// are bound, STATUS= lines, WATCHDOG=1 from the main loop, STOPPING=1. Outside systemd
/// (no NOTIFY_SOCKET) every call is a no-op.

#include <cstdint>
#include <string_view>

namespace pumptherm::daemon {

class SystemdNotifier {
 public:
  SystemdNotifier();
  void Ready(std::string_view status);
  void Status(std::string_view status);
  void Stopping();
  /// RELOADING=1 (systemd then waits for the next READY=1).
  void Reloading();
  /// Sends WATCHDOG=1 when at least half the watchdog interval has passed since the last one.
  /// `now_us` is monotonic time.
  void KickWatchdog(std::int64_t now_us);
  /// Half the WatchdogSec interval in microseconds, or 0 when no watchdog is configured.
  std::int64_t watchdog_half_period_us() const { return watchdog_half_us_; }

 private:
  std::int64_t watchdog_half_us_ = 0;
  std::int64_t last_kick_us_ = -1;
};

}  // namespace pumptherm::daemon
