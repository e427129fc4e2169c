// Test helper: a stand-in for systemd's notify socket. Binds an AF_UNIX datagram socket at
// argv[1] and prints each message on one line (newlines inside a message become " | "), until
// SIGTERM or argv[2] seconds have passed.
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

namespace {
volatile sig_atomic_t g_stop = 0;
void OnSignal(int) { g_stop = 1; }
}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: notify_listener SOCKET_PATH SECONDS\n");
    return 2;
  }
  signal(SIGTERM, OnSignal);
  const int fd = socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::strncpy(addr.sun_path, argv[1], sizeof addr.sun_path - 1);
  unlink(argv[1]);
  if (fd < 0 || bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) < 0) {
    std::perror("notify_listener: bind");
    return 1;
  }
  const time_t end = time(nullptr) + std::atoi(argv[2]);
  char buf[4096];
  while (!g_stop && time(nullptr) < end) {
    pollfd p{fd, POLLIN, 0};
    if (poll(&p, 1, 200) <= 0) continue;
    const ssize_t n = recv(fd, buf, sizeof buf - 1, 0);
    if (n <= 0) continue;
    std::string msg(buf, static_cast<std::size_t>(n));
    while (!msg.empty() && msg.back() == '\n') msg.pop_back();
    for (std::size_t i; (i = msg.find('\n')) != std::string::npos;) msg.replace(i, 1, " | ");
    std::printf("%s\n", msg.c_str());
    std::fflush(stdout);
  }
  close(fd);
  unlink(argv[1]);
  return 0;
}
