#include "daemon/systemd_notify.hpp"

#include <systemd/sd-daemon.h>

#include <string>

namespace pumptherm::daemon {

SystemdNotifier::SystemdNotifier() {
  std::uint64_t usec = 0;
  if (sd_watchdog_enabled(0, &usec) > 0) watchdog_half_us_ = static_cast<std::int64_t>(usec / 2);
}

void SystemdNotifier::Ready(std::string_view status) {
  sd_notify(0, ("READY=1\nSTATUS=" + std::string(status)).c_str());
}

void SystemdNotifier::Status(std::string_view status) {
  sd_notify(0, ("STATUS=" + std::string(status)).c_str());
}

void SystemdNotifier::Stopping() { sd_notify(0, "STOPPING=1\nSTATUS=stopping"); }

void SystemdNotifier::Reloading() { sd_notify(0, "RELOADING=1\nSTATUS=reloading"); }

void SystemdNotifier::KickWatchdog(std::int64_t now_us) {
  if (watchdog_half_us_ <= 0) return;
  if (last_kick_us_ >= 0 && now_us - last_kick_us_ < watchdog_half_us_) return;
  sd_notify(0, "WATCHDOG=1");
  last_kick_us_ = now_us;
}

}  // namespace pumptherm::daemon
