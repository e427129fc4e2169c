// A stand-in for SocketCAN on a kernel without it (this machine's: docs/testing.md), preloaded
// into pumpthermd by host-side tests (LD_PRELOAD): a CAN_RAW socket becomes a Unix datagram
// socket, bound to $CANSHIM_DIR/<interface>.gw; what the daemon sends goes to
// $CANSHIM_DIR/<interface>.bus (the test's bus, when it listens; otherwise it is dropped, as
// on a bus without listeners) with the time it was sent appended (8 bytes, CLOCK_MONOTONIC ns),
// and what the bus sends to <interface>.gw arrives as received frames (struct can_frame, 16
// bytes). Interface indexes and flags are made up (always up).
// Only what pumpthermd's CanSocket uses is covered: socket, ioctl, setsockopt, bind, send,
// close; recvmsg and getsockopt work on the Unix socket as they are.
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <linux/can.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#define MAX_FDS 1024

static char g_iface[MAX_FDS][IFNAMSIZ];  // per shim descriptor: its interface ("" until known)
static unsigned char g_shim[MAX_FDS];     // 1: a CAN socket stood in for

static int IsShim(int fd) { return fd >= 0 && fd < MAX_FDS && g_shim[fd]; }

static void PathOf(const char* iface, const char* end, struct sockaddr_un* a) {
  const char* dir = getenv("CANSHIM_DIR");
  memset(a, 0, sizeof *a);
  a->sun_family = AF_UNIX;
  snprintf(a->sun_path, sizeof a->sun_path, "%s/%s.%s", dir ? dir : "/tmp", iface, end);
}

int socket(int domain, int type, int protocol) {
  static int (*real)(int, int, int);
  if (!real) real = dlsym(RTLD_NEXT, "socket");
  if (domain != PF_CAN) return real(domain, type, protocol);
  const int fd = real(AF_UNIX, SOCK_DGRAM | (type & (SOCK_NONBLOCK | SOCK_CLOEXEC)), 0);
  if (fd >= 0 && fd < MAX_FDS) {
    g_shim[fd] = 1;
    g_iface[fd][0] = '\0';
  }
  return fd;
}

int ioctl(int fd, unsigned long request, ...) {
  static int (*real)(int, unsigned long, ...);
  if (!real) real = dlsym(RTLD_NEXT, "ioctl");
  va_list ap;
  va_start(ap, request);
  void* arg = va_arg(ap, void*);
  va_end(ap);
  if (!IsShim(fd)) return real(fd, request, arg);
  struct ifreq* ifr = arg;
  if (request == SIOCGIFINDEX) {
    snprintf(g_iface[fd], IFNAMSIZ, "%s", ifr->ifr_name);
    ifr->ifr_ifindex = 100 + (int)(strlen(ifr->ifr_name) % 50);
    return 0;
  }
  if (request == SIOCGIFFLAGS) {
    ifr->ifr_flags = IFF_UP | IFF_RUNNING;
    return 0;
  }
  errno = ENOTTY;
  return -1;
}

int setsockopt(int fd, int level, int name, const void* value, socklen_t len) {
  static int (*real)(int, int, int, const void*, socklen_t);
  if (!real) real = dlsym(RTLD_NEXT, "setsockopt");
  if (!IsShim(fd)) return real(fd, level, name, value, len);
  if (level == SOL_CAN_RAW) return 0;
  // SO_TIMESTAMP, SO_RCVBUF work on the Unix socket; what it refuses does not matter here.
  (void)real(fd, level, name, value, len);
  return 0;
}

int bind(int fd, const struct sockaddr* addr, socklen_t len) {
  static int (*real)(int, const struct sockaddr*, socklen_t);
  if (!real) real = dlsym(RTLD_NEXT, "bind");
  if (!IsShim(fd) || addr->sa_family != AF_CAN) return real(fd, addr, len);
  struct sockaddr_un a;
  PathOf(g_iface[fd], "gw", &a);
  unlink(a.sun_path);
  return real(fd, (const struct sockaddr*)&a, sizeof a);
}

ssize_t send(int fd, const void* buf, size_t n, int flags) {
  static ssize_t (*real)(int, const void*, size_t, int);
  if (!real) real = dlsym(RTLD_NEXT, "send");
  if (!IsShim(fd)) return real(fd, buf, n, flags);
  struct sockaddr_un a;
  PathOf(g_iface[fd], "bus", &a);
  // The frame, then when it was sent (CLOCK_MONOTONIC, ns): the bus records the daemon's own
  // timing, not its own reading delay.
  unsigned char out[CANFD_MTU + 8];
  if (n > CANFD_MTU) n = CANFD_MTU;
  memcpy(out, buf, n);
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  const long long t_ns = (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
  memcpy(out + n, &t_ns, sizeof t_ns);
  const ssize_t r = sendto(fd, out, n + sizeof t_ns, flags, (const struct sockaddr*)&a, sizeof a);
  // No bus listening: a frame nobody receives is still sent.
  if (r < 0 && (errno == ENOENT || errno == ECONNREFUSED)) return (ssize_t)n;
  return r < 0 ? r : (ssize_t)n;
}

int close(int fd) {
  static int (*real)(int);
  if (!real) real = dlsym(RTLD_NEXT, "close");
  if (IsShim(fd)) g_shim[fd] = 0;
  return real(fd);
}
