// The bad-input catalogue of docs/robustness.md, as a table: every input surface (CAN frames,
// DBC, config, model files, motor files, CSV, candump logs, LCM clear commands, saved state)
// against kinds of bad input, each row with the program's exact answer (the error text, or what
// is counted and dropped). Every row is checked here; with PUMPTHERM_CATALOGUE=1 in the
// environment the test prints the rows as the Markdown table of the docs.
#include <gtest/gtest.h>

#include <cstdlib>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "daemon/config.hpp"
#include "daemon/gateway.hpp"
#include "daemon/safety_state.hpp"
#include "estimators/motor.hpp"
#include "estimators/thermal_model.hpp"
#include "protocol/candump_log.hpp"
#include "protocol/dbc.hpp"
#include "pumptherm/alarm_clear_reply_t.hpp"
#include "tools/common/csv.hpp"

namespace pumptherm::daemon {
namespace {

struct Row {
  const char* surface;
  const char* kind;
  std::string input;                 // as shown in the docs
  std::function<std::string()> run;  // the answer: an error text, "accepted ..." or "counted ..."
  std::string expect;                // must occur in the answer
};

std::string Replace(std::string text, const std::string& from, const std::string& to) {
  const auto at = text.find(from);
  if (at == std::string::npos) throw std::logic_error("test: '" + from + "' not in the base text");
  return text.replace(at, from.size(), to);
}

// --- configuration ---
std::string ConfigVerdict(const std::string& text) {
  try {
    const DaemonConfig c = ParseConfig(text, "/etc/pumptherm/p.toml");
    return "accepted (" + std::to_string(c.pumps.size()) + " pumps)";
  } catch (const ConfigError& e) {
    return e.what();
  }
}
const std::string kPump = "[[pump]]\nname = \"a\"\nnode_id = 1\n";

// --- thermal model ---
const std::string kModel = R"([model]
name = "m"
[[node]]
name = "a"
capacity_J_per_K = 10.0
[[edge]]
between = ["a", "ambient"]
resistance_K_per_W = 1.0
)";
std::string Model(const std::string& text) {
  try {
    const auto m = estimators::ThermalModel::Parse(text, "m.toml");
    return "accepted (" + std::to_string(m.StateCount()) + " states)";
  } catch (const estimators::ThermalModelError& e) {
    return e.what();
  }
}

// --- motor description ---
const std::string kMotor = R"(name = "m"
pole_pairs = 1
rated_speed_rpm = 21000.0
flux_Wb = 0.0182
inductance_H = 0.24e-3
[resistance]
r0_ohm = 0.28
t0_degC = 27.2
alpha_per_K = 4.1e-3
)";
std::string Motor(const std::string& text) {
  try {
    estimators::ParseMotorDescription(text, "motor.toml");
    return "accepted";
  } catch (const estimators::MotorDescriptionError& e) {
    return e.what();
  }
}

// --- CSV (a tool reading time_s and iq_A) ---
std::string Csv(const std::string& text) {
  try {
    const auto t = tools::CsvTable::Parse(text, "in.csv");
    t.Time();
    t.Column("iq_A");
    return "accepted";
  } catch (const tools::CsvError& e) {
    return e.what();
  }
}

// --- candump log line ---
std::string Candump(const std::string& line) {
  const auto p = protocol::ParseCandumpLine(line);
  if (p.skip) return "skipped";
  if (p.ok) return "accepted (len " + std::to_string(p.record.frame.len) + ")";
  return "column " + std::to_string(p.column) + ": " + p.error;
}

// --- DBC ---
const std::string kDbc =
    "VERSION \"\"\n\nBU_: N\n\nBO_ 256 M: 8 N\n SG_ S : 0|16@1+ (0.1,0) [0|6553.5] \"A\" N\n";
std::string Dbc(const std::string& text) {
  try {
    const auto d = protocol::ParseDbc(text, "x.dbc");
    std::string answer = "accepted (" + std::to_string(d.messages.size()) + " messages)";
    for (const auto& p : d.problems) {
      answer += "; warning x.dbc:" + std::to_string(p.line) + ":" + std::to_string(p.column) +
                ": " + p.message;
    }
    return answer;
  } catch (const protocol::DbcError& e) {
    return e.what();
  }
}

// --- frames, clear commands and saved state through the gateway ---
/// The operators' and the gateway's keys of the catalogue: panel (listed), old-panel (listed,
/// revoked), mallory (not listed), the gateway's.
SigningKey Panel() { return SigningKey(Seed{1, 1}); }
SigningKey OldPanel() { return SigningKey(Seed{2, 2}); }
SigningKey Mallory() { return SigningKey(Seed{3, 3}); }
SigningKey BadInputGatewayKey() { return SigningKey(Seed{9, 9}); }

const std::string kGatewayConfig = R"(
[gateway]
heartbeat_period_s = 0
[[can]]
interface = "can0"
[alarms]
clear_can_interfaces = ["can0"]
[[alarms.clear_operators]]
name = "panel"
public_key = ")" + FormatPublicKey(Panel().public_key()) +
                                   R"("
[[alarms.clear_operators]]
name = "old-panel"
public_key = ")" + FormatPublicKey(OldPanel().public_key()) +
                                   R"("
revoked = true
[[pump]]
name = "tmp1"
node_id = 1
interface = "can0"
thermal_model = "tmp-generic"
)";

struct NullSink : OutputSink {
  void SendFrame(std::size_t, std::int64_t, const protocol::CanFrame&) override {}
  bool PublishLcm(const std::string&, std::int64_t, const std::vector<std::uint8_t>&) override {
    return true;
  }
};

/// Feeds one frame (hex payload) to a fresh gateway and names the counters it moved.
std::string Frame(std::uint32_t id, const std::string& hex, bool fd = false, bool remote = false,
                  bool error = false) {
  Gateway g(ParseConfig(kGatewayConfig, std::string(PUMPTHERM_SOURCE_DIR) + "/p.toml"));
  protocol::TimedFrame tf;
  tf.time_us = 1'700'000'000'000'000;
  tf.frame.id = id;
  tf.frame.fd = fd;
  tf.frame.remote = remote;
  tf.frame.error = error;
  tf.frame.len = static_cast<std::uint8_t>(hex.size() / 2);
  for (std::size_t i = 0; i < tf.frame.len; ++i) {
    tf.frame.data[i] = static_cast<std::uint8_t>(std::stoul(hex.substr(2 * i, 2), nullptr, 16));
  }
  g.OnFrame(g.Interface("can0"), tf);
  NullSink sink;
  g.Advance(tf.time_us, sink);
  const auto& gc = g.counters();
  const auto& pc = g.pumps()[0]->counters();
  std::string out;
  auto add = [&](const char* name, std::uint64_t v) {
    if (v > 0) out += (out.empty() ? "" : ", ") + std::string(name) + " " + std::to_string(v);
  };
  add("rx_unknown_id", gc.rx_unknown_id);
  add("rx_unconfigured_node", gc.rx_unconfigured_node);
  add("rx_bad_length", gc.rx_bad_length);
  add("rejected_values", pc.rejected_values);
  add("fast_frames", pc.fast_frames);
  add("status_frames", pc.status_frames);
  add("clears_accepted", gc.clears_accepted);
  add("clears_refused", gc.clears_refused);
  return out.empty() ? "counted by the interface only, ignored" : "counted: " + out;
}

std::string Clear(const std::string& pump, const std::string& source) {
  Gateway g(ParseConfig(kGatewayConfig, std::string(PUMPTHERM_SOURCE_DIR) + "/p.toml"));
  const bool ok = g.Clear(pump, source, "");
  return std::string(ok ? "accepted" : "refused") + ", logged; clears_accepted " +
         std::to_string(g.counters().clears_accepted) + ", clears_refused " +
         std::to_string(g.counters().clears_refused) + ", clears_unauthenticated " +
         std::to_string(g.counters().clears_unauthenticated);
}

constexpr std::int64_t kClearNowUs = 1'700'000'000'000'000;

/// Counts what a gateway with BadInputGatewayKey() made of LCM clear commands `messages` (nullptr:
/// bytes that did not decode), the replies it published and the verdict of the last one.
std::string LcmClear(const std::vector<const pumptherm::alarm_clear_t*>& messages) {
  Gateway g(ParseConfig(kGatewayConfig, std::string(PUMPTHERM_SOURCE_DIR) + "/p.toml"));
  g.SetGatewayKey(BadInputGatewayKey());
  g.LoadClearKeys("");
  struct ReplySink : NullSink {
    std::string last;
    int replies = 0;
    bool PublishLcm(const std::string& channel, std::int64_t,
                    const std::vector<std::uint8_t>& b) override {
      pumptherm::alarm_clear_reply_t r;
      if (r.decode(b.data(), 0, static_cast<int>(b.size())) > 0) {
        last = channel + ": " + r.reason;
        ++replies;
      }
      return true;
    }
  } sink;
  bool ok = false;
  for (const auto* m : messages) ok = g.ClearFromLcm(m, kClearNowUs, sink);
  return std::string(ok ? "accepted" : "refused") + ", logged; clears_accepted " +
         std::to_string(g.counters().clears_accepted) + ", clears_refused " +
         std::to_string(g.counters().clears_refused) + ", clears_unauthenticated " +
         std::to_string(g.counters().clears_unauthenticated) +
         (sink.replies == 0
              ? "; no reply"
              : "; " + std::to_string(sink.replies) + " reply, the last " + sink.last);
}

/// A clear command for `pump` of gateway `gateway`, node `node`, signed with `key` (nullptr:
/// not signed, with `key_id` claimed).
pumptherm::alarm_clear_t ClearCommand(const std::string& pump, const SigningKey* key,
                                      std::int64_t utime = kClearNowUs, std::int64_t counter = 5,
                                      const std::string& gateway = "pumptherm",
                                      const std::string& node = "") {
  pumptherm::alarm_clear_t m;
  m.utime = utime;
  m.gateway = gateway;
  m.pump = pump;
  m.node = node;
  m.key_id = Panel().key_id();
  m.comment = "";
  m.counter = counter;
  std::fill(std::begin(m.tag), std::end(m.tag), std::uint8_t{0});
  std::fill(std::begin(m.signature), std::end(m.signature), std::uint8_t{0});
  if (key) SignCommand(*key, BadInputGatewayKey().public_key(), "PUMPTHERM", m);
  return m;
}

/// What ParseSafetyState makes of the text of a valid safety state changed by `change`.
std::string SafetyText(const std::function<std::string(std::string)>& change) {
  SafetyState s;
  s.latched["tmp1"] = {{"winding", 130.0}};
  s.counters["tmp1"]["0123456789abcdef"] = 42;
  std::string problem;
  return ParseSafetyState(change(FormatSafetyState(s)), &problem)
             ? "read"
             : "refused: " + problem + "; the pumps latch 'safety state lost'";
}

std::string LcmClear(const pumptherm::alarm_clear_t& m) { return LcmClear({&m}); }

/// A valid saved state of the test gateway's pump, from a short run.
std::string SavedState() {
  Gateway g(ParseConfig(kGatewayConfig, std::string(PUMPTHERM_SOURCE_DIR) + "/p.toml"));
  NullSink sink;
  const std::size_t iface = g.Interface("can0");
  for (int k = 0; k < 30; ++k) {
    protocol::TimedFrame tf;
    tf.time_us = 1'700'000'000'000'000 + std::int64_t{k} * 100'000;
    tf.frame.id = 0x181;  // PUMP_STATUS of node 1: 800 rpm, frame and ambient 25 degC
    tf.frame.len = 8;
    const std::uint64_t bits = 400ULL | (2ULL << 16) | (750ULL << 19) | (750ULL << 31);
    for (int i = 0; i < 8; ++i)
      tf.frame.data[static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(bits >> (8 * i));
    g.OnFrame(iface, tf);
    g.Advance(tf.time_us, sink);
  }
  return g.SaveState();
}

std::string Restore(const std::string& text) {
  Gateway g(ParseConfig(kGatewayConfig, std::string(PUMPTHERM_SOURCE_DIR) + "/p.toml"));
  std::string warning;
  const int n = g.RestoreState(text, 1'700'000'010'000'000, &warning);
  return "restored " + std::to_string(n) + (warning.empty() ? "" : "; " + warning);
}

std::vector<Row> Catalogue() {
  const std::string state = SavedState();
  const auto first_x = state.find("x_degC = [ ") + 11;
  std::vector<Row> rows = {
      // --- configuration ---
      {"config", "truncated", "`[gateway`", [] { return ConfigVerdict("[gateway"); }, "p.toml:1:"},
      {"config", "wrong type", "`heartbeat_period_s = \"1\"`",
       [] { return ConfigVerdict("[gateway]\nheartbeat_period_s = \"1\"\n"); },
       "heartbeat_period_s"},
      {"config", "out of range", "`thermal_period_s = 0`",
       [] { return ConfigVerdict("[gateway]\nthermal_period_s = 0\n"); }, "thermal_period_s"},
      {"config", "NaN", "`thermal_period_s = nan`",
       [] { return ConfigVerdict("[gateway]\nthermal_period_s = nan\n"); }, "thermal_period_s"},
      {"config", "Inf", "`heartbeat_period_s = inf`",
       [] { return ConfigVerdict("[gateway]\nheartbeat_period_s = inf\n"); }, "heartbeat_period_s"},
      {"config", "duplicate", "two `[[pump]]` named `a`",
       [] { return ConfigVerdict(kPump + "[[pump]]\nname = \"a\"\nnode_id = 2\n"); },
       "listed twice"},
      {"config", "duplicate", "a key twice",
       [] { return ConfigVerdict("[gateway]\nname = \"x\"\nname = \"y\"\n"); }, "p.toml:3:"},
      {"config", "unknown", "`[gateway] colour = 1`",
       [] { return ConfigVerdict("[gateway]\ncolour = 1\n"); }, "colour"},
      {"config", "huge", "`node_id = 99999999999`",
       [] { return ConfigVerdict("[[pump]]\nname = \"a\"\nnode_id = 99999999999\n"); }, "node_id"},
      {"config", "empty", "empty file", [] { return ConfigVerdict(""); }, "accepted (0 pumps)"},
      {"config", "non-UTF-8", "`name = \"\\xff\"`",
       [] { return ConfigVerdict("[gateway]\nname = \"\xff\"\n"); }, "p.toml:2:"},
      {"config", "wrong value", "pump name with `/`",
       [] { return ConfigVerdict("[[pump]]\nname = \"a/b\"\nnode_id = 1\n"); }, "name"},
      // --- thermal model ---
      {"model", "truncated", "file cut after `capacity_J_per_K =`",
       [] { return Model(kModel.substr(0, kModel.find("10.0"))); }, "m.toml:"},
      {"model", "wrong type", "`capacity_J_per_K = \"ten\"`",
       [] { return Model(Replace(kModel, "10.0", "\"ten\"")); }, "capacity_J_per_K"},
      {"model", "out of range", "`capacity_J_per_K = -1`",
       [] { return Model(Replace(kModel, "10.0", "-1.0")); }, "capacity"},
      {"model", "NaN", "`capacity_J_per_K = nan`",
       [] { return Model(Replace(kModel, "10.0", "nan")); }, "capacity"},
      {"model", "Inf", "`resistance_K_per_W = inf`",
       [] { return Model(Replace(kModel, "= 1.0", "= inf")); }, "resistance"},
      {"model", "out of range", "`resistance_K_per_W = 0`",
       [] { return Model(Replace(kModel, "= 1.0", "= 0.0")); }, "resistance"},
      {"model", "duplicate", "node `a` twice",
       [] { return Model(kModel + "[[node]]\nname = \"a\"\ncapacity_J_per_K = 1.0\n"); },
       "declared twice"},
      {"model", "unknown", "edge to node `b`",
       [] { return Model(Replace(kModel, "\"a\", \"ambient\"", "\"b\", \"ambient\"")); }, "b"},
      {"model", "unknown", "key `colour`",
       [] { return Model(Replace(kModel, "[[edge]]", "colour = 1\n[[edge]]")); }, "colour"},
      {"model", "empty", "empty file", [] { return Model(""); }, "m.toml"},
      {"model", "non-UTF-8", "node name `\\xff`",
       [] { return Model(Replace(kModel, "name = \"a\"", "name = \"\xff\"")); }, "m.toml:"},
      // --- motor description ---
      {"motor", "truncated", "no `[resistance]`",
       [] { return Motor(kMotor.substr(0, kMotor.find("[resistance]"))); }, "resistance"},
      {"motor", "wrong type", "`pole_pairs = 1.5`",
       [] { return Motor(Replace(kMotor, "pole_pairs = 1", "pole_pairs = 1.5")); }, "pole_pairs"},
      {"motor", "out of range", "`pole_pairs = 0`",
       [] { return Motor(Replace(kMotor, "pole_pairs = 1", "pole_pairs = 0")); }, "pole_pairs"},
      {"motor", "NaN", "`flux_Wb = nan`", [] { return Motor(Replace(kMotor, "0.0182", "nan")); },
       "flux_Wb"},
      {"motor", "Inf", "`r0_ohm = inf`", [] { return Motor(Replace(kMotor, "0.28", "inf")); },
       "r0_ohm"},
      {"motor", "duplicate", "`flux_Wb` twice",
       [] { return Motor(Replace(kMotor, "inductance_H", "flux_Wb = 1.0\ninductance_H")); },
       "motor.toml:"},
      {"motor", "unknown", "`fluxx_Wb = 1`",
       [] { return Motor(Replace(kMotor, "inductance_H", "fluxx_Wb = 1.0\ninductance_H")); },
       "fluxx_Wb"},
      {"motor", "huge", "`rated_speed_rpm = 1e400`",
       [] { return Motor(Replace(kMotor, "21000.0", "1e400")); }, "motor.toml:"},
      {"motor", "empty", "empty file", [] { return Motor(""); }, "motor.toml"},
      // --- CSV ---
      {"CSV", "truncated", "last row cut: `0.2`",
       [] { return Csv("time_s,iq_A\n0,1\n0.1,2\n0.2\n"); }, "row 4"},
      {"CSV", "wrong type", "`iq_A` cell `abc`", [] { return Csv("time_s,iq_A\n0,1\n0.1,abc\n"); },
       "iq_A"},
      {"CSV", "NaN", "`iq_A` cell `nan`", [] { return Csv("time_s,iq_A\n0,1\n0.1,nan\n"); },
       "iq_A"},
      {"CSV", "Inf", "`iq_A` cell `inf`", [] { return Csv("time_s,iq_A\n0,1\n0.1,inf\n"); },
       "iq_A"},
      {"CSV", "huge", "`iq_A` cell `1e999`", [] { return Csv("time_s,iq_A\n0,1\n0.1,1e999\n"); },
       "iq_A"},
      {"CSV", "out of order", "time goes back",
       [] { return Csv("time_s,iq_A\n0,1\n0.1,2\n0.05,3\n"); }, "time_s"},
      {"CSV", "duplicate", "column `iq_A` twice", [] { return Csv("time_s,iq_A,iq_A\n0,1,1\n"); },
       "twice"},
      {"CSV", "unknown", "no `iq_A` column", [] { return Csv("time_s,id_A\n0,1\n"); }, "iq_A"},
      {"CSV", "empty", "empty file", [] { return Csv(""); }, "empty"},
      {"CSV", "empty", "empty cell", [] { return Csv("time_s,iq_A\n0,\n"); }, "iq_A"},
      {"CSV", "non-UTF-8", "cell `\\xff`", [] { return Csv("time_s,iq_A\n0,\xff\n"); }, "iq_A"},
      // --- candump log lines ---
      {"candump log", "truncated", "`(1.0) can0 12`", [] { return Candump("(1.0) can0 12"); },
       "column"},
      {"candump log", "wrong length", "`123#1` (odd hex digits)",
       [] { return Candump("(1.0) can0 123#1"); }, "column"},
      {"candump log", "wrong length", "9 data bytes, classic",
       [] { return Candump("(1.0) can0 123#001122334455667788"); }, "column"},
      {"candump log", "out of range", "`800#00` (11-bit ID above 7FF)",
       [] { return Candump("(1.0) can0 800#00"); }, "column"},
      {"candump log", "out of range", "`40000123#00` (CAN ID above 29 bits)",
       [] { return Candump("(1.0) can0 40000123#00"); }, "column 12: CAN ID above 29 bits"},
      {"candump log", "out of range", "remote length 9 `123#R9`",
       [] { return Candump("(1.0) can0 123#R9"); }, "column"},
      {"candump log", "wrong type", "time `(abc)`", [] { return Candump("(abc) can0 123#00"); },
       "column 2"},
      {"candump log", "huge", "time of 30 digits",
       [] { return Candump("(999999999999999999999999999999.0) can0 123#00"); }, "column"},
      {"candump log", "empty", "empty line", [] { return Candump(""); }, "skipped"},
      {"candump log", "non-UTF-8", "data `\\xff\\xff`",
       [] { return Candump("(1.0) can0 123#\xff\xff"); }, "column"},
      // --- DBC ---
      {"DBC", "truncated", "`SG_` line cut after the start bit",
       [] { return Dbc(kDbc.substr(0, kDbc.find("@"))); }, "x.dbc:6:"},
      // Accepted with a warning: the signal decodes as not available, the frames decode.
      {"DBC", "wrong length", "signal past the 8 bytes of its message",
       [] { return Dbc(Replace(kDbc, "0|16@", "60|16@")); }, "accepted"},
      {"DBC", "huge", "signal past 64 bytes", [] { return Dbc(Replace(kDbc, "0|16@", "510|16@")); },
       "beyond 64 bytes"},
      {"DBC", "duplicate", "message 256 twice", [] { return Dbc(kDbc + "BO_ 256 M2: 8 N\n"); },
       "x.dbc:"},
      {"DBC", "wrong type", "length `eight`", [] { return Dbc(Replace(kDbc, "M: 8", "M: eight")); },
       "x.dbc:5:"},
      {"DBC", "empty", "empty file", [] { return Dbc(""); }, "accepted (0 messages)"},
      // --- CAN frames (PUMP_FAST_I of node 1 is 0x101, PUMP_STATUS 0x181, PUMP_CLEAR 0x701) ---
      {"CAN frame", "wrong length", "PUMP_FAST_I with 4 bytes",
       [] { return Frame(0x101, "00000000"); }, "rx_bad_length 1"},
      {"CAN frame", "unknown", "ID 0x123", [] { return Frame(0x123, "0000000000000000"); },
       "rx_unknown_id 1"},
      {"CAN frame", "unknown", "PUMP_FAST_I of node 2 (not configured)",
       [] { return Frame(0x102, "0000000000000000"); }, "rx_unknown_id 1, rx_unconfigured_node 1"},
      {"CAN frame", "NaN", "PUMP_FAST_I, Id_A not-available (0x8000)",
       [] { return Frame(0x101, "0080000000000000"); }, "rejected_values 1"},
      {"CAN frame", "huge", "PUMP_FAST_I as a 64-byte CAN FD frame",
       [] { return Frame(0x101, std::string(128, '0'), true); }, "fast_frames 1"},
      {"CAN frame", "wrong type", "remote frame on 0x101",
       [] { return Frame(0x101, "", false, true); }, "ignored"},
      {"CAN frame", "wrong type", "error frame",
       [] { return Frame(0x004, "0000000000000000", false, false, true); }, "ignored"},
      {"CAN frame", "empty", "PUMP_STATUS with 0 bytes", [] { return Frame(0x181, ""); },
       "rx_bad_length 1"},
      // --- clear commands (LCM alarm_clear_t and PUMP_CLEAR frames) ---
      {"LCM clear", "spoofed", "panel's key ID, no tag or signature",
       [] { return LcmClear(ClearCommand("tmp1", nullptr)); },
       "refused, logged; clears_accepted 0, clears_refused 1, clears_unauthenticated 1; no reply"},
      {"LCM clear", "spoofed", "panel's key ID, signed with another key",
       [] {
         const SigningKey m = Mallory();
         auto c = ClearCommand("tmp1", &m);
         c.key_id = Panel().key_id();
         return LcmClear(c);
       },
       "clears_unauthenticated 1; no reply"},
      {"LCM clear", "unknown", "signed with a key not in alarms.clear_operators",
       [] {
         const SigningKey m = Mallory();
         return LcmClear(ClearCommand("tmp1", &m));
       },
       "clears_unauthenticated 1; no reply"},
      {"LCM clear", "spoofed", "source `panel` by name, through the unsigned path",
       [] { return Clear("tmp1", "panel"); },
       "refused, logged; clears_accepted 0, clears_refused 1, clears_unauthenticated 1"},
      {"LCM clear", "replayed", "a valid command received twice",
       [] {
         const SigningKey k = Panel();
         const auto m = ClearCommand("tmp1", &k);
         return LcmClear({&m, &m});
       },
       "refused, logged; clears_accepted 1, clears_refused 1, clears_unauthenticated 0; 1 reply"},
      {"LCM clear", "revoked", "signed with old-panel's revoked key",
       [] {
         const SigningKey k = OldPanel();
         return LcmClear(ClearCommand("tmp1", &k));
       },
       "refused, logged; clears_accepted 0, clears_refused 1, clears_unauthenticated 0; no reply"},
      {"LCM clear", "other gateway", "a valid command for gateway `hall9`",
       [] {
         const SigningKey k = Panel();
         return LcmClear(ClearCommand("tmp1", &k, kClearNowUs, 5, "hall9"));
       },
       "no reply"},
      {"LCM clear", "old", "a valid command issued 31 s ago",
       [] {
         const SigningKey k = Panel();
         return LcmClear(ClearCommand("tmp1", &k, kClearNowUs - 31'000'000));
       },
       "window 30 s"},
      {"LCM clear", "huge", "a valid command with `utime` INT64_MIN",
       [] {
         const SigningKey k = Panel();
         return LcmClear(ClearCommand("tmp1", &k, std::numeric_limits<std::int64_t>::min()));
       },
       "refused"},
      {"LCM clear", "unknown", "a valid command for node `frame`, which is not latched",
       [] {
         const SigningKey k = Panel();
         return LcmClear(ClearCommand("tmp1", &k, kClearNowUs, 5, "pumptherm", "frame"));
       },
       "node 'frame' has no latched trip"},
      {"LCM clear", "unknown", "pump `nope`",
       [] {
         const SigningKey k = Panel();
         return LcmClear(ClearCommand("nope", &k));
       },
       "refused, logged; clears_accepted 0, clears_refused 1, clears_unauthenticated 0; no reply"},
      {"LCM clear", "wrong type", "bytes that do not decode as alarm_clear_t",
       [] { return LcmClear({nullptr}); }, "clears_unauthenticated 1; no reply"},
      {"LCM clear", "valid", "signed with panel's key, new counter",
       [] {
         const SigningKey k = Panel();
         return LcmClear(ClearCommand("tmp1", &k));
       },
       "accepted, logged; clears_accepted 1, clears_refused 0"},
      {"CAN clear", "unknown", "PUMP_CLEAR on `can:can1`", [] { return Clear("tmp1", "can:can1"); },
       "refused"},
      // --- saved state ---
      {"saved state", "valid", "a state saved by the same gateway",
       [state] { return Restore(state); }, "restored 1"},
      {"saved state", "truncated", "the file cut in half",
       [state] { return Restore(state.substr(0, state.size() / 2)); }, "restored 0"},
      {"saved state", "empty", "empty file", [] { return Restore(""); }, "restored 0"},
      {"saved state", "NaN", "first temperature `nan`",
       [state, first_x] {
         return Restore(state.substr(0, first_x) + "nan" + state.substr(state.find(',', first_x)));
       },
       "restored 0; saved state of pump(s) tmp1 does not fit"},
      {"saved state", "huge", "first temperature `1e300`",
       [state, first_x] {
         return Restore(state.substr(0, first_x) + "1e300" +
                        state.substr(state.find(',', first_x)));
       },
       "restored 0; saved state of pump(s) tmp1 does not fit"},
      {"saved state", "NaN", "held input `speed_rpm = nan`",
       [state] {
         return Restore(Replace(state, "speed_rpm = ", "speed_rpm = nan\nold_speed_rpm = "));
       },
       "does not fit the configuration or is damaged"},
      {"saved state", "wrong length", "one temperature missing",
       [state, first_x] {
         return Restore(state.substr(0, first_x) + state.substr(state.find(',', first_x) + 2));
       },
       "restored 0"},
      {"saved state", "unknown", "`version = 7`",
       [state] { return Restore(Replace(state, "version = 2", "version = 7")); },
       "unknown version"},
      {"saved state", "wrong length", "`resistance_probability = [ 0.5 ]` (two hypotheses)",
       [state] {
         return Restore(
             Replace(state, "resistance_probability = [",
                     "resistance_probability = [ 0.5 ]\nold_resistance_probability = ["));
       },
       "does not fit the configuration or is damaged"},
      {"saved state", "out of range", "`resistance_probability = [ 1.5, 0.1 ]`",
       [state] {
         return Restore(
             Replace(state, "resistance_probability = [",
                     "resistance_probability = [ 1.5, 0.1 ]\nold_resistance_probability = ["));
       },
       "does not fit the configuration or is damaged"},
      {"saved state", "wrong type", "`resistance_rejections = [ 0.5, 0 ]`",
       [state] {
         return Restore(
             Replace(state, "resistance_rejections = [",
                     "resistance_rejections = [ 0.5, 0 ]\nold_resistance_rejections = ["));
       },
       "does not fit the configuration or is damaged"},
      {"saved state", "wrong type", "`model = \"other\"`",
       [state] { return Restore(Replace(state, "model = 'tmp-generic'", "model = 'other'")); },
       "restored 0"},
      {"saved state", "non-UTF-8", "a byte `\\xff` in a key",
       [state] { return Restore(Replace(state, "version", "ver\xffsion")); }, "restored 0"},
      // --- the safety state (safety.toml: latched trips and clear counters) ---
      {"safety state", "valid", "as the gateway writes it",
       [] { return SafetyText([](std::string t) { return t; }); }, "read"},
      {"safety state", "damaged", "`winding` changed to `Winding` (still TOML)",
       [] {
         return SafetyText([](std::string t) { return Replace(t, "'winding'", "'Winding'"); });
       },
       "the checksum does not match"},
      {"safety state", "empty", "cut short after 40 bytes",
       [] { return SafetyText([](std::string t) { return t.substr(0, 40); }); },
       "no checksum line"},
      {"safety state", "empty", "an empty file",
       [] { return SafetyText([](std::string) { return std::string(); }); }, "no checksum line"},
  };
  return rows;
}

TEST(BadInput, EveryRowOfTheCatalogueGivesItsAnswer) {
  const bool print = std::getenv("PUMPTHERM_CATALOGUE") != nullptr;
  if (print) std::printf("| surface | kind | input | answer |\n| --- | --- | --- | --- |\n");
  for (const Row& r : Catalogue()) {
    const std::string answer = r.run();
    EXPECT_NE(answer.find(r.expect), std::string::npos)
        << r.surface << " / " << r.kind << " / " << r.input << ": answer '" << answer << "' lacks '"
        << r.expect << "'";
    if (print) {
      std::string a = answer;
      for (char& c : a) {
        if (c == '|') c = '/';
        if (c == '\n') c = ' ';
        if (static_cast<unsigned char>(c) >= 0x80) c = '?';
      }
      std::printf("| %s | %s | %s | %s |\n", r.surface, r.kind, r.input.c_str(), a.c_str());
    }
  }
}

// A frame of a mapped message from a node ID no pump has: a warning naming the node ID and the
// pump of that interface not heard from (a wrong node_id), at most once a minute per node.
TEST(UnconfiguredNode, WarnsOnceAMinuteNamingTheSilentPump) {
  Gateway g(ParseConfig(kGatewayConfig, std::string(PUMPTHERM_SOURCE_DIR) + "/p.toml"));
  protocol::TimedFrame tf;
  tf.frame.id = 0x102;  // PUMP_FAST_I of node 2; tmp1 is node 1 and silent
  tf.frame.len = 8;
  testing::internal::CaptureStderr();
  for (int k = 0; k < 100; ++k) {
    tf.time_us = 1'700'000'000'000'000 + k * 1'000'000;  // 100 s at 1 Hz
    g.OnFrame(g.Interface("can0"), tf);
  }
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_EQ(g.counters().rx_unconfigured_node, 100u);
  EXPECT_NE(
      err.find("can0: PUMP_FAST_I frames (ID 102) from node ID 2, which no pump on can0 has; not "
               "heard from yet there: tmp1 (node_id 1) - is its node_id wrong?"),
      std::string::npos)
      << err;
  std::size_t lines = 0;
  for (std::size_t at = err.find("node ID 2"); at != std::string::npos;
       at = err.find("node ID 2", at + 1))
    ++lines;
  EXPECT_EQ(lines, 2u) << "one warning at 0 s and one at 60 s:\n" << err;
}

}  // namespace
// A configured pump that is never heard from raises stale telemetry after stale_after_s (2 s by
// default), as one that fell silent: in its snapshot, on CAN (GW_ALARM level 1, reason 4) and in
// the status line; its temperatures stay "not available".
TEST(NeverHeardPump, RaisesStaleTelemetryOnCanAndInTheStatusLine) {
  Gateway g(ParseConfig(kGatewayConfig, std::string(PUMPTHERM_SOURCE_DIR) + "/p.toml"));
  struct Frames : OutputSink {
    std::vector<protocol::CanFrame> sent;
    void SendFrame(std::size_t, std::int64_t, const protocol::CanFrame& f) override {
      sent.push_back(f);
    }
    bool PublishLcm(const std::string&, std::int64_t, const std::vector<std::uint8_t>&) override {
      return true;
    }
  } sink;
  const std::int64_t t0 = 1'700'000'000'000'000;
  g.Advance(t0, sink);
  EXPECT_EQ(g.pumps()[0]->snapshot().alarm.level, estimators::AlarmLevel::kNone);
  EXPECT_NE(g.StatusLine().find("1 never heard"), std::string::npos) << g.StatusLine();
  for (int k = 1; k <= 10; ++k) g.Advance(t0 + k * 1'000'000, sink);
  const auto& a = g.pumps()[0]->snapshot().alarm;
  EXPECT_EQ(a.level, estimators::AlarmLevel::kWarning);
  EXPECT_EQ(a.reason, estimators::AlarmReason::kStaleTelemetry);
  EXPECT_NE(g.StatusLine().find("1 warning"), std::string::npos) << g.StatusLine();
  EXPECT_NE(g.PumpTable().find("never heard; warning (stale telemetry)"), std::string::npos)
      << g.PumpTable();
  bool alarm_frame = false;
  for (const auto& f : sink.sent) {
    if (f.id == 0x201)
      alarm_frame = alarm_frame || (f.data[0] & 0x3) == 1;  // GW_ALARM of node 1: warning
  }
  EXPECT_TRUE(alarm_frame) << sink.sent.size() << " frames sent";
}

}  // namespace pumptherm::daemon
