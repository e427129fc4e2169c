#pragma once
/// The network boundary of LCM's receiving side (docs/threat-model.md, "The network boundary").
/// LCM 1.3's udpm provider binds its receiving socket to every address and joins the group on
/// the interface the routing table names, so any host on that segment can send to the daemon,
/// whatever the URL's ttl (which only limits how far the daemon's own messages go). LCM offers
/// no source filter, so the daemon attaches one to LCM's socket itself: a classic BPF socket
/// filter (SO_ATTACH_FILTER, no privilege needed) that keeps a datagram only when this host sent
/// it (looped back: pkt_type PACKET_LOOPBACK, or received on the loopback interface) or when it
/// came in on an interface the configuration names; the kernel drops the rest before LCM reads
/// them, and counts them in the socket's drop counter.

#include <linux/filter.h>

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace pumptherm::daemon {

/// The port of an LCM udpm URL ("udpm://239.255.76.67:7667?ttl=0"; LCM's default 7667 when the
/// URL names none, "udpm://" alone meaning LCM's default group); nullopt for another provider.
std::optional<std::uint16_t> UdpmPort(std::string_view url);

/// The filter: keep what was looped back by this host, what came in on interface `lo_ifindex`,
/// and what came in on an interface in `ifindexes`; drop everything else.
std::vector<sock_filter> HostOnlyFilter(int lo_ifindex, const std::vector<int>& ifindexes);

/// The descriptor of this process's UDP socket bound to `port` (LCM's receiving socket), found
/// among /proc/self/fd; nullopt when there is none.
std::optional<int> FindUdpSocketBoundTo(std::uint16_t port);

/// Attaches `filter` to socket `fd`. Throws std::system_error naming what failed.
void AttachFilter(int fd, const std::vector<sock_filter>& filter);

/// Datagrams socket `fd` dropped so far (SO_MEMINFO: the filter's and a full buffer's), or
/// nullopt when the kernel does not say.
std::optional<std::uint64_t> SocketDrops(int fd);

}  // namespace pumptherm::daemon
