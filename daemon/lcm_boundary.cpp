#include "daemon/lcm_boundary.hpp"

#include <dirent.h>
#include <linux/if_packet.h>
#include <linux/sock_diag.h>
#include <netinet/in.h>
#include <sys/socket.h>

#include <cerrno>
#include <charconv>
#include <cstdlib>
#include <system_error>

namespace pumptherm::daemon {
namespace {

constexpr std::uint16_t kLcmDefaultPort = 7667;

sock_filter Stmt(std::uint16_t code, std::uint32_t k) { return BPF_STMT(code, k); }
sock_filter Jump(std::uint16_t code, std::uint32_t k, std::uint8_t jt, std::uint8_t jf) {
  return BPF_JUMP(code, k, jt, jf);
}

}  // namespace

std::optional<std::uint16_t> UdpmPort(std::string_view url) {
  constexpr std::string_view kScheme = "udpm://";
  if (url.substr(0, kScheme.size()) != kScheme) return std::nullopt;
  std::string_view rest = url.substr(kScheme.size());
  rest = rest.substr(0, rest.find('?'));
  const std::size_t colon = rest.rfind(':');
  if (colon == std::string_view::npos) return kLcmDefaultPort;
  unsigned port = 0;
  const std::string_view digits = rest.substr(colon + 1);
  const auto [end, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), port);
  if (ec != std::errc() || end != digits.data() + digits.size() || port == 0 || port > 65535)
    return std::nullopt;
  return static_cast<std::uint16_t>(port);
}

std::vector<sock_filter> HostOnlyFilter(int lo_ifindex, const std::vector<int>& ifindexes) {
  // A: the packet type; looped back by this host's own multicast loop: keep.
  // Then A: the interface it came in on; the loopback interface or a listed one: keep.
  const auto n = static_cast<std::uint8_t>(ifindexes.size());
  std::vector<sock_filter> f;
  f.push_back(
      Stmt(BPF_LD | BPF_W | BPF_ABS, static_cast<std::uint32_t>(SKF_AD_OFF + SKF_AD_PKTTYPE)));
  // Jump offsets count from the next instruction: to "keep" at the end (n + 3 ahead).
  f.push_back(
      Jump(BPF_JMP | BPF_JEQ | BPF_K, PACKET_LOOPBACK, static_cast<std::uint8_t>(n + 3), 0));
  f.push_back(
      Stmt(BPF_LD | BPF_W | BPF_ABS, static_cast<std::uint32_t>(SKF_AD_OFF + SKF_AD_IFINDEX)));
  f.push_back(Jump(BPF_JMP | BPF_JEQ | BPF_K, static_cast<std::uint32_t>(lo_ifindex),
                   static_cast<std::uint8_t>(n + 1), 0));
  for (std::uint8_t i = 0; i < n; ++i) {
    f.push_back(Jump(BPF_JMP | BPF_JEQ | BPF_K, static_cast<std::uint32_t>(ifindexes[i]),
                     static_cast<std::uint8_t>(n - i), 0));
  }
  f.push_back(Stmt(BPF_RET | BPF_K, 0));           // drop
  f.push_back(Stmt(BPF_RET | BPF_K, 0xffffffff));  // keep, whole
  return f;
}

std::optional<int> FindUdpSocketBoundTo(std::uint16_t port) {
  DIR* dir = ::opendir("/proc/self/fd");
  if (!dir) return std::nullopt;
  std::optional<int> found;
  while (dirent* e = ::readdir(dir)) {
    const int fd = std::atoi(e->d_name);
    if (fd <= 2 || fd == ::dirfd(dir)) continue;
    int type = 0;
    socklen_t type_len = sizeof type;
    sockaddr_in addr{};
    socklen_t len = sizeof addr;
    if (::getsockopt(fd, SOL_SOCKET, SO_TYPE, &type, &type_len) != 0 || type != SOCK_DGRAM)
      continue;
    if (::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) != 0) continue;
    if (addr.sin_family == AF_INET && ntohs(addr.sin_port) == port) {
      found = fd;
      break;
    }
  }
  ::closedir(dir);
  return found;
}

void AttachFilter(int fd, const std::vector<sock_filter>& filter) {
  sock_fprog prog{};
  prog.len = static_cast<unsigned short>(filter.size());
  prog.filter = const_cast<sock_filter*>(filter.data());
  if (::setsockopt(fd, SOL_SOCKET, SO_ATTACH_FILTER, &prog, sizeof prog) != 0)
    throw std::system_error(errno, std::generic_category(), "SO_ATTACH_FILTER on LCM's socket");
}

std::optional<std::uint64_t> SocketDrops(int fd) {
  std::uint32_t meminfo[SK_MEMINFO_VARS] = {};
  socklen_t len = sizeof meminfo;
  if (::getsockopt(fd, SOL_SOCKET, SO_MEMINFO, meminfo, &len) != 0 ||
      len <= SK_MEMINFO_DROPS * sizeof(std::uint32_t)) {
    return std::nullopt;
  }
  return meminfo[SK_MEMINFO_DROPS];
}

}  // namespace pumptherm::daemon
