#include "daemon/live_loop.hpp"

#include <signal.h>
#include <sys/epoll.h>
#include <sys/signalfd.h>
#include <sys/timerfd.h>
#include <time.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <limits>
#include <system_error>
#include <vector>

#include "daemon/can_socket.hpp"
#include "daemon/log.hpp"
#include "daemon/systemd_notify.hpp"
#include "daemon/unique_fd.hpp"

namespace pumptherm::daemon {
namespace {

constexpr std::uint64_t kSignalTag = 0;
constexpr std::uint64_t kTimerTag = 1;
constexpr std::uint64_t kFirstSocketTag = 2;
constexpr std::int64_t kReopenPeriodUs = 1000000;   // retry a removed interface every second
constexpr int kRxBudget = 256;                      // frames per socket per wake-up (fairness)

[[noreturn]] void ThrowErrno(const char* what) {
  throw std::system_error(errno, std::generic_category(), what);
}

std::int64_t MonotonicUs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000 + ts.tv_nsec / 1000;
}

}  // namespace

struct LiveLoop::Impl {
  const DaemonConfig& config;
  Gateway& gateway;
  UniqueFd epoll;
  UniqueFd signal_fd;
  UniqueFd timer_fd;
  std::vector<CanSocket> sockets;          // one per configured interface, same order
  std::vector<std::size_t> gateway_index;  // gateway interface index per socket
  std::vector<std::uint32_t> last_drop_total;
  SystemdNotifier notifier;
  std::int64_t next_status_us = 0;
  std::int64_t next_reopen_us = 0;
  bool stop = false;

  Impl(const DaemonConfig& c, Gateway& g) : config(c), gateway(g) {}

  void Watch(std::size_t i) {
    epoll_event ev{};
    ev.events = EPOLLIN;
    ev.data.u64 = kFirstSocketTag + i;
    if (epoll_ctl(epoll.get(), EPOLL_CTL_ADD, sockets[i].fd(), &ev) < 0) ThrowErrno("epoll_ctl(CAN socket)");
  }

  void MarkUp(std::size_t i, bool up) {
    InterfaceCounters& c = gateway.counters(gateway_index[i]);
    if (c.up == up) return;
    c.up = up;
    if (up) {
      Log(LogLevel::kNotice, "{}: interface is up again; receiving", sockets[i].name());
    } else {
      Log(LogLevel::kWarning, "{}: interface is down; waiting for it", sockets[i].name());
    }
  }

  void Drain(std::size_t i) {
    CanSocket& s = sockets[i];
    protocol::TimedFrame tf;
    for (int k = 0; k < kRxBudget && s.is_open(); ++k) {
      std::uint32_t drops_total = last_drop_total[i];
      switch (s.Receive(&tf, &drops_total)) {
        case RxStatus::kFrame: {
          InterfaceCounters& c = gateway.counters(gateway_index[i]);
          if (drops_total != last_drop_total[i]) {
            c.rx_queue_drops += drops_total - last_drop_total[i];  // unsigned wrap is right
            last_drop_total[i] = drops_total;
          }
          MarkUp(i, true);
          gateway.OnFrame(gateway_index[i], tf);
          break;
        }
        case RxStatus::kEmpty:
          return;
        case RxStatus::kDown:
          MarkUp(i, false);
          return;
        case RxStatus::kGone:
          Log(LogLevel::kWarning, "{}: interface was removed; will reopen it when it returns",
              s.name());
          gateway.counters(gateway_index[i]).up = false;
          s.Close();  // closing also removes it from the epoll set
          return;
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
        continue;
      }
      try {
        sockets[i] = CanSocket::Open(config.interfaces[i].name, config.interfaces[i].error_frames);
        last_drop_total[i] = 0;
        Watch(i);
        Log(LogLevel::kNotice, "{}: interface is back; socket reopened", sockets[i].name());
        MarkUp(i, sockets[i].InterfaceUp());
      } catch (const std::system_error&) {
        // Still absent; try again at the next reopen tick.
      }
    }
  }

  void SendHeartbeat(std::int64_t now_us) {
    while (auto frame = gateway.HeartbeatDue(now_us)) {
      for (std::size_t i = 0; i < sockets.size(); ++i) {
        if (!sockets[i].is_open()) continue;
        InterfaceCounters& c = gateway.counters(gateway_index[i]);
        switch (sockets[i].Send(*frame)) {
          case TxStatus::kSent: ++c.tx_frames; break;
          case TxStatus::kDown: ++c.tx_dropped; MarkUp(i, false); break;
          default: ++c.tx_dropped; break;
        }
      }
    }
  }

  void ArmTimer(std::int64_t now_us) {
    std::int64_t next = std::min({gateway.NextHeartbeatUs(), next_status_us, next_reopen_us});
    const std::int64_t wd = notifier.watchdog_half_period_us();
    if (wd > 0) next = std::min(next, now_us + wd);
    next = std::max(next, now_us + 1000);  // at least 1 ms ahead
    itimerspec its{};
    its.it_value.tv_sec = next / 1000000;
    its.it_value.tv_nsec = (next % 1000000) * 1000;
    if (timerfd_settime(timer_fd.get(), TFD_TIMER_ABSTIME, &its, nullptr) < 0) ThrowErrno("timerfd_settime");
  }

  void OnTimer() {
    std::uint64_t expirations = 0;
    if (::read(timer_fd.get(), &expirations, sizeof expirations) < 0 && errno != EAGAIN) {
      Log(LogLevel::kWarning, "timerfd read: {}", std::strerror(errno));
    }
    const std::int64_t now = MonotonicUs();
    SendHeartbeat(now);
    if (now >= next_reopen_us) {
      Reopen();
      next_reopen_us = now + kReopenPeriodUs;
    }
    if (now >= next_status_us) {
      notifier.Status(gateway.StatusLine());
      next_status_us = now + static_cast<std::int64_t>(config.gateway.status_period_s * 1e6);
    }
    notifier.KickWatchdog(now);
    ArmTimer(now);
  }

  void OnSignal() {
    signalfd_siginfo si{};
    while (::read(signal_fd.get(), &si, sizeof si) == static_cast<ssize_t>(sizeof si)) {
      switch (si.ssi_signo) {
        case SIGTERM:
        case SIGINT:
          Log(LogLevel::kNotice, "{} received; stopping", si.ssi_signo == SIGTERM ? "SIGTERM" : "SIGINT");
          stop = true;
          break;
        case SIGHUP:
          Log(LogLevel::kNotice, "SIGHUP received: configuration reload is not implemented yet; "
                                 "the running configuration stays");
          break;
        default:
          break;
      }
    }
  }
};

LiveLoop::LiveLoop(const DaemonConfig& config, Gateway& gateway)
    : impl_(std::make_unique<Impl>(config, gateway)) {
  Impl& m = *impl_;
  if (config.interfaces.empty()) {
    throw std::system_error(EINVAL, std::generic_category(),
                            config.source + ": no [[can]] interface configured (use -r LOG for a log)");
  }
  m.epoll = UniqueFd(epoll_create1(EPOLL_CLOEXEC));
  if (!m.epoll.valid()) ThrowErrno("epoll_create1");

  sigset_t mask;
  sigemptyset(&mask);
  sigaddset(&mask, SIGTERM);
  sigaddset(&mask, SIGINT);
  sigaddset(&mask, SIGHUP);
  if (sigprocmask(SIG_BLOCK, &mask, nullptr) < 0) ThrowErrno("sigprocmask");
  m.signal_fd = UniqueFd(signalfd(-1, &mask, SFD_NONBLOCK | SFD_CLOEXEC));
  if (!m.signal_fd.valid()) ThrowErrno("signalfd");
  m.timer_fd = UniqueFd(timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC));
  if (!m.timer_fd.valid()) ThrowErrno("timerfd_create");

  epoll_event ev{};
  ev.events = EPOLLIN;
  ev.data.u64 = kSignalTag;
  if (epoll_ctl(m.epoll.get(), EPOLL_CTL_ADD, m.signal_fd.get(), &ev) < 0) ThrowErrno("epoll_ctl(signalfd)");
  ev.data.u64 = kTimerTag;
  if (epoll_ctl(m.epoll.get(), EPOLL_CTL_ADD, m.timer_fd.get(), &ev) < 0) ThrowErrno("epoll_ctl(timerfd)");

  for (const InterfaceConfig& iface : config.interfaces) {
    m.sockets.push_back(CanSocket::Open(iface.name, iface.error_frames));
    m.gateway_index.push_back(gateway.Interface(iface.name));
    m.last_drop_total.push_back(0);
    m.Watch(m.sockets.size() - 1);
  }
}

LiveLoop::~LiveLoop() = default;

int LiveLoop::Run() {
  Impl& m = *impl_;
  const std::int64_t start = MonotonicUs();
  m.next_status_us = start;
  m.next_reopen_us = start + kReopenPeriodUs;
  std::string names;
  for (const auto& s : m.sockets) names += (names.empty() ? "" : ", ") + s.name();
  Log(LogLevel::kNotice, "listening on {}", names);
  m.notifier.Ready("listening on " + names);
  m.ArmTimer(start);

  epoll_event events[16];
  while (!m.stop) {
    const int n = epoll_wait(m.epoll.get(), events, 16, -1);
    if (n < 0) {
      if (errno == EINTR) continue;
      Log(LogLevel::kError, "epoll_wait: {}", std::strerror(errno));
      return 1;
    }
    for (int k = 0; k < n; ++k) {
      const std::uint64_t tag = events[k].data.u64;
      if (tag == kSignalTag) {
        m.OnSignal();
      } else if (tag == kTimerTag) {
        m.OnTimer();
      } else {
        m.Drain(static_cast<std::size_t>(tag - kFirstSocketTag));
      }
    }
  }
  m.notifier.Stopping();
  return 0;
}

}  // namespace pumptherm::daemon
