// `pumpthermd -r LOG --lcm-log FILE` writes the LCM messages as an LCM log file
// that lcm-logplayer plays. This reads the file back with LCM's own log reader (lcm::LogFile,
// the reader lcm-logplayer uses) and decodes every event with the type its channel names
// (docs/lcm.md): the file is a well-formed LCM log, every message decodes to exactly its
// length, the timestamps are the frames' (non-decreasing, within the recording), and the
// temperatures in it are the ones the gateway estimated. The vcan test daemon_live_demo plays a
// file written so with the real lcm-logplayer in the guest.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <lcm/lcm-cpp.hpp>
#include <map>
#include <string>

#include "daemon/config.hpp"
#include "daemon/gateway.hpp"
#include "daemon/offline.hpp"
#include "pumptherm/alarm_t.hpp"
#include "pumptherm/gateway_health_t.hpp"
#include "pumptherm/telemetry_t.hpp"
#include "pumptherm/temperatures_t.hpp"

namespace pumptherm::daemon {
namespace {

/// Decodes `ev` as T; true when the message decodes to exactly the event's length.
template <typename T>
bool DecodesExactly(const lcm::LogEvent& ev, T* out) {
  return out->decode(ev.data, 0, ev.datalen) == ev.datalen;
}

TEST(LcmLog, OfflineLogReadsBackWithLcmsReaderAndDecodesByChannel) {
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "lcm_log_test";
  std::filesystem::create_directories(dir);
  const std::string lcm_path = (dir / "gateway.lcm").string();

  const DaemonConfig config =
      LoadConfig(std::string(PUMPTHERM_SOURCE_DIR) + "/tools/demo/pumpthermd-demo.toml");
  Gateway gateway(config);
  std::ifstream in(PUMPTHERM_RECORDING);
  ASSERT_TRUE(in) << PUMPTHERM_RECORDING << ": cannot open (built by vcan_pipeline_recording)";
  OfflineOptions options;
  options.lcm_log = lcm_path;
  const OfflineResult r = RunOffline(in, "pipeline.log", gateway, options);
  ASSERT_GT(r.lcm_out, 100U);

  // The recording's time span, for the timestamps.
  std::int64_t first_us = -1, last_us = -1;
  {
    std::ifstream rec(PUMPTHERM_RECORDING);
    std::string line;
    while (std::getline(rec, line)) {
      if (line.size() < 3 || line[0] != '(') continue;
      const std::int64_t t = std::llround(std::stod(line.substr(1)) * 1e6);
      if (first_us < 0) first_us = t;
      last_us = t;
    }
  }

  lcm::LogFile log(lcm_path, "r");
  ASSERT_TRUE(log.good()) << lcm_path;
  std::map<std::string, int> per_channel;
  std::uint64_t events = 0;
  std::int64_t previous_us = 0;
  std::int64_t previous_eventnum = -1;
  std::map<std::string, double> last_frame_degC;
  while (const lcm::LogEvent* ev = log.readNextEvent()) {
    ++events;
    ++per_channel[ev->channel];
    EXPECT_GT(ev->eventnum, previous_eventnum) << "event numbers must increase";
    previous_eventnum = ev->eventnum;
    EXPECT_GE(ev->timestamp, previous_us) << ev->channel << ": timestamps must not go back";
    EXPECT_GE(ev->timestamp, first_us) << ev->channel;
    EXPECT_LE(ev->timestamp, last_us + 1'000'000) << ev->channel;
    previous_us = ev->timestamp;
    const std::string& ch = ev->channel;
    const auto ends_with = [&](const char* s) { return ch.ends_with(s); };
    if (ends_with("/TEMPS")) {
      pumptherm::temperatures_t m;
      ASSERT_TRUE(DecodesExactly(*ev, &m)) << ch;
      // utime is the estimate's time (the last thermal step), the event's the publishing time.
      EXPECT_LE(m.utime, ev->timestamp) << ch;
      EXPECT_GE(m.utime, ev->timestamp - 1'000'000) << ch << ": older than one thermal period";
      EXPECT_EQ(ch, "PUMPTHERM/" + m.pump + "/TEMPS");
      ASSERT_EQ(m.num_nodes, static_cast<int>(m.node_names.size()));
      for (int k = 0; k < m.num_nodes; ++k) {
        const double t = m.node_degC[static_cast<std::size_t>(k)];
        // NaN means "no estimate yet"; otherwise a motor on a 22 degC bench, 100 s in.
        if (!std::isnan(t)) {
          EXPECT_GT(t, 0.0) << ch << " " << m.node_names[static_cast<std::size_t>(k)];
          EXPECT_LT(t, 150.0) << ch << " " << m.node_names[static_cast<std::size_t>(k)];
        }
        if (m.node_names[static_cast<std::size_t>(k)] == "frame") last_frame_degC[m.pump] = t;
      }
    } else if (ends_with("/TELEMETRY")) {
      pumptherm::telemetry_t m;
      ASSERT_TRUE(DecodesExactly(*ev, &m)) << ch;
    } else if (ends_with("/ALARM")) {
      pumptherm::alarm_t m;
      ASSERT_TRUE(DecodesExactly(*ev, &m)) << ch;
    } else if (ch == "PUMPTHERM/GATEWAY/HEALTH") {
      pumptherm::gateway_health_t m;
      ASSERT_TRUE(DecodesExactly(*ev, &m)) << ch;
    } else {
      ADD_FAILURE() << "unexpected channel " << ch;
    }
  }
  EXPECT_EQ(events, r.lcm_out) << "every message handed to the log is in it";
  for (const char* pump : {"pump1", "pump2", "pump3"}) {
    for (const char* kind : {"TELEMETRY", "TEMPS", "ALARM"}) {
      EXPECT_GT(per_channel[std::string("PUMPTHERM/") + pump + "/" + kind], 0)
          << pump << " " << kind;
    }
    // The last TEMPS in the log carries the gateway's final frame estimate (published at the
    // thermal period, so it is at most one step older: in these first seconds, while the filter
    // settles, the frame estimate moves a few tenths of a kelvin per step at most).
    const auto& pumps = gateway.pumps();
    for (const auto& p : pumps) {
      if (p->config().name != pump) continue;
      const auto& names = p->model().StateNames();
      for (std::size_t k = 0; k < names.size(); ++k) {
        if (names[k] == "frame") {
          EXPECT_NEAR(last_frame_degC[pump], p->snapshot().node_degC[k], 0.5) << pump;
        }
      }
    }
  }
  EXPECT_GT(per_channel["PUMPTHERM/GATEWAY/HEALTH"], 0);
  for (const auto& [ch, n] : per_channel) std::printf("%-28s %6d\n", ch.c_str(), n);
}

}  // namespace
}  // namespace pumptherm::daemon
