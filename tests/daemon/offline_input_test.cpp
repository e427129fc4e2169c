// What `pumpthermd -r` (RunOffline) makes of its input and writes: a recording made with
// candump -t z or -t d runs as the same recording with Unix stamps does (same thermal steps,
// same estimates), a log that is empty, junk or a directory says so naming the file, the
// heartbeat is in the output log as live, and a paced run publishes on LCM as it goes (what
// `pumptherm replay --pace` uses). The recording is the vcan pipeline's (the plant's demo, 100 s).
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <lcm/lcm-cpp.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "daemon/config.hpp"
#include "daemon/gateway.hpp"
#include "daemon/offline.hpp"
#include "protocol/candump_log.hpp"

namespace pumptherm::daemon {
namespace {

namespace fs = std::filesystem;

DaemonConfig DemoConfig() {
  return LoadConfig(std::string(PUMPTHERM_SOURCE_DIR) + "/tools/demo/pumpthermd-demo.toml");
}

std::vector<std::string> RecordingLines() {
  std::ifstream in(PUMPTHERM_RECORDING);
  EXPECT_TRUE(in) << PUMPTHERM_RECORDING << ": cannot open (built by vcan_pipeline_recording)";
  std::vector<std::string> lines;
  std::string line;
  while (std::getline(in, line)) lines.push_back(line);
  return lines;
}

/// The recording as candump's screen format with -t z (time since the first frame) or -t d
/// (since the previous frame): " (000.010000)  can0  101   [8]  11 22 ...", as candump.c's
/// "(%03lu.%06lu) " and sprint_long_canframe write it.
std::string Relative(const std::vector<std::string>& lines, bool delta) {
  std::string out;
  std::int64_t first = -1, previous = -1;
  for (const auto& l : lines) {
    const protocol::CandumpParse p = protocol::ParseCandumpLine(l);
    if (!p.ok) continue;
    const std::int64_t t = p.record.time_us;
    if (first < 0) first = previous = t;
    const std::int64_t shown = delta ? t - previous : t - first;
    previous = t;
    const protocol::CanFrame& f = p.record.frame;
    out += fmt::format(" ({:03}.{:06})  {}  {:03X}   [{}] ", shown / 1000000, shown % 1000000,
                       p.record.interface, f.id, static_cast<unsigned>(f.len));
    for (int i = 0; i < f.len; ++i)
      out += fmt::format(" {:02X}", static_cast<unsigned>(f.data[static_cast<std::size_t>(i)]));
    out += '\n';
  }
  return out;
}

struct Outcome {
  OfflineResult result;
  std::vector<std::uint64_t> steps;
  std::vector<std::vector<double>> nodes_degC;
};

Outcome RunText(const std::string& text, OfflineOptions options = {}) {
  Gateway gateway(DemoConfig());
  std::istringstream in(text);
  Outcome o;
  o.result = RunOffline(in, "recording", gateway, options);
  for (const auto& p : gateway.pumps()) {
    o.steps.push_back(p->counters().thermal_steps);
    o.nodes_degC.push_back(p->snapshot().node_degC);
  }
  return o;
}

TEST(OfflineInput, RelativeStampsRunAsTheRecordingDoes) {
  const std::vector<std::string> lines = RecordingLines();
  std::string absolute;
  for (const auto& l : lines) absolute += l + '\n';
  const Outcome a = RunText(absolute);
  const Outcome z = RunText(Relative(lines, false));
  const Outcome d = RunText(Relative(lines, true));
  EXPECT_EQ(a.result.time_base, protocol::CandumpTimeBase::kAbsolute);
  EXPECT_EQ(z.result.time_base, protocol::CandumpTimeBase::kSinceFirst);
  EXPECT_EQ(d.result.time_base, protocol::CandumpTimeBase::kSincePrevious);
  EXPECT_EQ(z.result.frames, a.result.frames);
  EXPECT_EQ(d.result.frames, a.result.frames);
  // 100 s of telemetry: a thermal step per second per pump, on every clock.
  ASSERT_EQ(a.steps.size(), 3u);
  for (std::size_t p = 0; p < a.steps.size(); ++p) {
    EXPECT_GE(a.steps[p], 95u);
    EXPECT_EQ(z.steps[p], a.steps[p]) << "pump " << p;
    EXPECT_EQ(d.steps[p], a.steps[p]) << "pump " << p;
    for (std::size_t k = 0; k < a.nodes_degC[p].size(); ++k) {
      EXPECT_NEAR(z.nodes_degC[p][k], a.nodes_degC[p][k], 1e-6) << "pump " << p << " node " << k;
      EXPECT_NEAR(d.nodes_degC[p][k], a.nodes_degC[p][k], 1e-6) << "pump " << p << " node " << k;
    }
  }
  // The time base is classified from the first stamps; -t d's sum gives the recording's span.
  EXPECT_EQ(d.result.last_us - d.result.first_us, a.result.last_us - a.result.first_us);
  EXPECT_EQ(z.result.first_us, 0);
}

TEST(OfflineInput, EmptyJunkAndDirectoryLogsSayWhatWasWrong) {
  const Outcome empty = RunText("");
  try {
    RequireFrames(empty.result, "e.log");
    ADD_FAILURE() << "an empty log passed";
  } catch (const std::runtime_error& e) {
    EXPECT_STREQ(e.what(), "e.log: empty: no frame to run on");
  }
  const Outcome junk = RunText("not a log\n\n   can0  123   [2]  11 22\n");
  try {
    RequireFrames(junk.result, "j.log");
    ADD_FAILURE() << "a junk log passed";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("j.log: no frame to run on in 3 lines: 1 not candump "
                                         "lines, 1 without a timestamp, 1 blank or comments"),
              std::string::npos)
        << e.what();
  }
  const fs::path dir = fs::path(::testing::TempDir()) / "offline_input_dir.log";
  fs::create_directories(dir);
  try {
    OpenLog(dir.string());
    ADD_FAILURE() << "a directory opened as a log";
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()), dir.string() + ": is a directory, not a candump log");
  }
}

TEST(OfflineInput, HeartbeatIsInTheOutputLogAsLive) {
  const std::vector<std::string> lines = RecordingLines();
  std::string text;
  for (const auto& l : lines) text += l + '\n';
  OfflineOptions options;
  const fs::path out = fs::path(::testing::TempDir()) / "offline_input_heartbeat.log";
  options.output_log = out.string();
  const Outcome o = RunText(text, options);
  std::ifstream in(out);
  std::string line;
  int beats = 0;
  std::uint32_t last_uptime = 0;
  while (std::getline(in, line)) {
    const protocol::CandumpParse p = protocol::ParseCandumpLine(line);
    ASSERT_TRUE(p.ok) << line;
    if (p.record.frame.id != 0x7F0) continue;
    EXPECT_EQ(p.record.interface, "can0");
    const auto& d = p.record.frame.data;
    last_uptime = static_cast<std::uint32_t>(d[0] | d[1] << 8 | d[2] << 16 | d[3] << 24);
    ++beats;
  }
  // One a second (heartbeat_period_s = 1) over the recording's span, on the one interface.
  const double span_s = static_cast<double>(o.result.last_us - o.result.first_us) * 1e-6;
  EXPECT_NEAR(beats, std::floor(span_s) + 1, 1.0);
  EXPECT_NEAR(last_uptime, std::floor(span_s), 1.0);
}

TEST(OfflineInput, PacedRunPublishesOnLcmAsItGoes) {
  const std::vector<std::string> lines = RecordingLines();
  std::string text;
  for (std::size_t i = 0; i < lines.size() && i < 15000; ++i) text += lines[i] + '\n';
  lcm::LCM lcm("memq://");
  ASSERT_TRUE(lcm.good());
  struct Counter {
    int n = 0;
    void On(const lcm::ReceiveBuffer*, const std::string&) { ++n; }
  } temps;
  lcm.subscribe("PUMPTHERM/pump1/TEMPS", &Counter::On, &temps);
  OfflineOptions options;
  options.lcm_publish = &lcm;
  options.pace = 1000.0;  // 1000 log seconds per second
  const Outcome o = RunText(text, options);
  while (lcm.handleTimeout(0) > 0) {
  }
  const double span_s = static_cast<double>(o.result.last_us - o.result.first_us) * 1e-6;
  EXPECT_GT(span_s, 20.0);
  // lcm.period_s = 1: a TEMPS message per second of the recording.
  EXPECT_NEAR(temps.n, span_s, 2.0);
}

}  // namespace
}  // namespace pumptherm::daemon
