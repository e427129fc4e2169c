// A test tool for the end-to-end clear tests (tests/daemon/clear_e2e_test.sh): what an attacker
// on the LCM group can do, in three modes.
//
//   lcm_clear_tool capture URL CHANNEL FILE TIMEOUT_S   the first message on CHANNEL into FILE
//   lcm_clear_tool publish URL CHANNEL FILE              FILE's bytes once onto CHANNEL (a replay,
//                                                        also onto another gateway's channel)
//   lcm_clear_tool flood URL PREFIX PUMP GATEWAY RATE DURATION_S KEY_ID...
//        forged alarm_clear_t (random tags and signatures, fresh counters, the time now) at RATE
//        per second for DURATION_S, the key IDs in turn (one source each); prints how many went
//        out and the rate reached.
//
// Exit 0 when done, 1 on failure (no message within TIMEOUT_S, LCM refused), 2 on bad arguments.
#include <sodium.h>
#include <time.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <lcm/lcm-cpp.hpp>
#include <string>
#include <thread>
#include <vector>

#include "protocol/lcm/channels.hpp"
#include "pumptherm/alarm_clear_t.hpp"

namespace {

std::int64_t WallUs() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000 + ts.tv_nsec / 1000;
}

int Capture(const std::string& url, const std::string& channel, const std::string& file,
            double timeout_s) {
  lcm::LCM lcm(url);
  if (!lcm.good()) return 1;
  struct Sink {
    std::vector<std::uint8_t> bytes;
    bool got = false;
    void On(const lcm::ReceiveBuffer* rbuf, const std::string&) {
      if (got) return;
      const auto* p = static_cast<const std::uint8_t*>(rbuf->data);
      bytes.assign(p, p + rbuf->data_size);
      got = true;
    }
  } sink;
  lcm.subscribe(channel, &Sink::On, &sink);
  std::printf("capturing %s\n", channel.c_str());
  std::fflush(stdout);
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (!sink.got && std::chrono::steady_clock::now() < end) lcm.handleTimeout(50);
  if (!sink.got) return 1;
  std::ofstream out(file, std::ios::binary);
  out.write(reinterpret_cast<const char*>(sink.bytes.data()),
            static_cast<std::streamsize>(sink.bytes.size()));
  return out ? 0 : 1;
}

int Publish(const std::string& url, const std::string& channel, const std::string& file) {
  std::ifstream in(file, std::ios::binary);
  const std::vector<char> bytes((std::istreambuf_iterator<char>(in)),
                                std::istreambuf_iterator<char>());
  if (bytes.empty()) return 1;
  lcm::LCM lcm(url);
  if (!lcm.good()) return 1;
  return lcm.publish(channel, bytes.data(), static_cast<unsigned>(bytes.size())) == 0 ? 0 : 1;
}

int Flood(const std::string& url, const std::string& prefix, const std::string& pump,
          const std::string& gateway, double rate, double duration_s,
          const std::vector<std::string>& key_ids) {
  if (sodium_init() < 0 || !(rate > 0) || !(duration_s > 0) || key_ids.empty()) return 2;
  lcm::LCM lcm(url);
  if (!lcm.good()) return 1;
  const std::string channel = pumptherm::lcm_channels::PumpChannelName(
      prefix, pump, pumptherm::lcm_channels::PumpChannel::kAlarmClear);
  pumptherm::alarm_clear_t m;
  m.gateway = gateway;
  m.pump = pump;
  m.node = "";
  m.comment = "forged";
  std::vector<std::uint8_t> bytes;
  const auto start = std::chrono::steady_clock::now();
  const auto end = start + std::chrono::duration<double>(duration_s);
  std::uint64_t sent = 0, failed = 0;
  for (auto now = start; now < end; now = std::chrono::steady_clock::now()) {
    // Paced in 1 ms slices: as many as the rate allows by now.
    const double elapsed_s = std::chrono::duration<double>(now - start).count();
    const auto due = static_cast<std::uint64_t>(elapsed_s * rate);
    while (sent + failed < due) {
      m.utime = WallUs();
      m.counter = m.utime + static_cast<std::int64_t>(sent);  // fresh, so the cheap checks pass
      m.key_id = key_ids[(sent + failed) % key_ids.size()];
      randombytes_buf(m.tag, sizeof m.tag);
      randombytes_buf(m.signature, sizeof m.signature);
      bytes.resize(static_cast<std::size_t>(m.getEncodedSize()));
      m.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
      if (lcm.publish(channel, bytes.data(), static_cast<unsigned>(bytes.size())) == 0) {
        ++sent;
      } else {
        ++failed;
      }
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  const double took_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("flood: %llu forged clears sent (%llu failed) in %.2f s: %.0f per s\n",
              static_cast<unsigned long long>(sent), static_cast<unsigned long long>(failed),
              took_s, static_cast<double>(sent) / took_s);
  return failed == 0 ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  const std::vector<std::string> a(argv + 1, argv + argc);
  if (a.size() == 5 && a[0] == "capture") return Capture(a[1], a[2], a[3], std::atof(a[4].c_str()));
  if (a.size() == 4 && a[0] == "publish") return Publish(a[1], a[2], a[3]);
  if (a.size() >= 8 && a[0] == "flood") {
    return Flood(a[1], a[2], a[3], a[4], std::atof(a[5].c_str()), std::atof(a[6].c_str()),
                 std::vector<std::string>(a.begin() + 7, a.end()));
  }
  std::fprintf(stderr,
               "usage: lcm_clear_tool capture URL CHANNEL FILE TIMEOUT_S | publish URL CHANNEL "
               "FILE | flood URL PREFIX PUMP GATEWAY RATE DURATION_S KEY_ID...\n");
  return 2;
}
