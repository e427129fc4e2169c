// pumptherm dbc check FILE            load a DBC, list its messages and signals, report problems
// pumptherm dbc decode --dbc FILE [LOG] candump log (file or stdin) -> JSON lines, CSV, or the
//                                       log annotated line by line as cantools decode does
// pumptherm dbc export --config FILE    the site's DBC: per pump, at the bus's IDs, nodes named
#include <fmt/format.h>
#include <fmt/ranges.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "daemon/config.hpp"
#include "daemon/gateway.hpp"
#include "daemon/published_fields.hpp"
#include "daemon/resources.hpp"
#include "protocol/candump_log.hpp"
#include "protocol/codec.hpp"
#include "protocol/dbc.hpp"
#include "protocol/dbc_writer.hpp"
#include "protocol/mapping.hpp"
#include "shipped/shipped_files.hpp"
#include "tools/pumptherm/subcommand.hpp"

namespace pumptherm::tools {
namespace {

using protocol::ByteOrder;
using protocol::Dbc;
using protocol::DbcMessage;
using protocol::DbcSignal;

std::string ReadWholeFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(fmt::format("{}: cannot open", path));
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// A DBC named by path, or a shipped one by its bare name ("pumptherm"), as the config names it.
Dbc LoadDbc(const std::string& reference) {
  std::string path;
  try {
    path = shipped::Resolve(shipped::FileKind::kDbc, reference);
  } catch (const std::runtime_error& e) {
    throw InputError(e.what());
  }
  try {
    return protocol::ParseDbc(ReadWholeFile(path), path);
  } catch (const protocol::DbcError& e) {
    throw InputError(e.what());
  }
}

std::string IdText(const DbcMessage& m) {
  return m.extended ? fmt::format("0x{:08X}x", m.id) : fmt::format("0x{:03X}", m.id);
}

int Check(const std::string& path, bool strict) {
  const Dbc dbc = LoadDbc(path);
  std::size_t signals = 0;
  for (const auto& m : dbc.messages) signals += m.signals.size();
  fmt::print("{}: {} messages, {} signals, {} nodes, version \"{}\"\n", path, dbc.messages.size(),
             signals, dbc.nodes.size(), dbc.version);
  for (const auto& m : dbc.messages) {
    const std::string cycle = m.cycle_time_ms && *m.cycle_time_ms > 0
                                  ? fmt::format("{} ms", *m.cycle_time_ms)
                                  : std::string("no cycle time");
    fmt::print("{} {} {} bytes, {}, from {}\n", IdText(m), m.name, m.size_bytes, cycle,
               m.transmitter);
    for (const auto& s : m.signals) {
      std::string mux;
      if (s.is_multiplexer) mux += " multiplexer";
      if (!s.multiplexer_switch.empty()) {
        mux += fmt::format(" when {} in", s.multiplexer_switch);
        for (const auto& r : s.multiplexer_ranges) {
          mux += r.low == r.high ? fmt::format(" {}", r.low) : fmt::format(" {}-{}", r.low, r.high);
        }
      }
      const char* type = s.value_type == protocol::SignalValueType::kFloat32   ? " float"
                         : s.value_type == protocol::SignalValueType::kFloat64 ? " double"
                         : s.is_signed                                         ? " signed"
                                                                               : " unsigned";
      fmt::print(
          "  {} {}|{}@{}{} x{} {:+} [{}, {}] \"{}\"{}{}\n", s.name, s.start_bit, s.length_bits,
          s.byte_order == ByteOrder::kLittleEndian ? 1 : 0, type, s.factor, s.offset, s.minimum,
          s.maximum, s.unit,
          s.not_available_raw ? fmt::format(" n/a raw {}", *s.not_available_raw) : std::string(),
          mux);
    }
  }
  for (const auto& p : dbc.problems) {
    fmt::print(stderr, "{}:{}:{}: warning: {}\n", dbc.file_name, p.line, p.column, p.message);
  }
  if (!dbc.problems.empty()) {
    fmt::print(stderr, "{}: {} problem(s)\n", dbc.file_name, dbc.problems.size());
    if (strict) return 2;
  }
  if (dbc.messages.empty()) {
    fmt::print(stderr, "{}: warning: no messages\n", dbc.file_name);
    if (strict) return 2;
  }
  return 0;
}

/// JSON string body with quotes and backslashes escaped (names here are plain ASCII).
std::string JsonEscape(std::string_view s) {
  std::string out;
  for (char c : s) {
    if (c == '"' || c == '\\') out.push_back('\\');
    if (static_cast<unsigned char>(c) < 0x20) {
      out += fmt::format("\\u{:04x}", c);
      continue;
    }
    out.push_back(c);
  }
  return out;
}

/// 15 significant digits: raw * factor + offset without binary noise (308.4, not
/// 308.40000000000003).
std::string Number(double v) {
  return std::isfinite(v) ? fmt::format("{:.15g}", v) : std::string();
}

/// Bad log lines warned about one by one; the rest are only counted.
constexpr std::size_t kMaxReportedBadLines = 10;

struct DecodeOptions {
  std::string dbc_path;
  std::string log_path;  // empty or "-": stdin
  std::string format = "json";
  std::vector<std::string> messages;
  unsigned node_id_limit = 1;
  bool single_line = false;
};

/// The DBC message a frame is (CAN ID = DBC ID + node ID, node below the limit), or index -1.
struct FrameMatch {
  int index = -1;
  unsigned node = 0;
};

FrameMatch MatchFrame(const protocol::DbcCodec& codec, const protocol::CanFrame& f,
                      unsigned node_id_limit) {
  for (unsigned node = 0; node < node_id_limit && node <= f.id; ++node) {
    const int index = codec.Find(f.id - node, f.extended);
    if (index >= 0) return {index, node};
  }
  return {};
}

/// Whether a signal is in this frame: always, or its multiplexer's raw value is in its ranges.
bool SignalPresent(const DbcMessage& m, std::size_t i, const std::vector<double>& values) {
  const DbcSignal& s = m.signals[i];
  if (s.multiplexer_switch.empty()) return true;
  for (std::size_t k = 0; k < m.signals.size(); ++k) {
    const DbcSignal& sw = m.signals[k];
    if (sw.name != s.multiplexer_switch || !std::isfinite(values[k])) continue;
    const double raw = std::round((values[k] - sw.offset) / sw.factor);
    for (const auto& r : s.multiplexer_ranges) {
      if (raw >= static_cast<double>(r.low) && raw <= static_cast<double>(r.high)) return true;
    }
  }
  return false;
}

/// One signal as cantools decode prints it: "Name: value unit", or "Name: label" for a value
/// with a VAL_ description; "n/a" for the declared not-available raw value.
std::string CantoolsSignal(const DbcSignal& s, double value) {
  // NaN here is the declared not-available raw value, which may have a label of its own.
  const std::optional<std::int64_t> raw =
      std::isfinite(value)
          ? std::optional<std::int64_t>(std::llround((value - s.offset) / s.factor))
          : s.not_available_raw;
  if (raw) {
    if (const auto it = s.value_descriptions.find(*raw); it != s.value_descriptions.end()) {
      return fmt::format("{}: {}", s.name, it->second);
    }
  }
  if (!std::isfinite(value)) return fmt::format("{}: n/a", s.name);
  return s.unit.empty() ? fmt::format("{}: {}", s.name, Number(value))
                        : fmt::format("{}: {} {}", s.name, Number(value), s.unit);
}

/// The text cantools decode appends after " ::" to a frame's line: the message name (with the
/// node ID when it is not 0) and its signals, on one line or one signal per indented line.
std::string CantoolsMessage(const DbcMessage& m, unsigned node, const std::vector<double>& values,
                            bool single_line) {
  std::vector<std::string> signals;
  for (std::size_t i = 0; i < m.signals.size(); ++i) {
    if (SignalPresent(m, i, values)) signals.push_back(CantoolsSignal(m.signals[i], values[i]));
  }
  const std::string name = node == 0 ? m.name : fmt::format("{}[node {}]", m.name, node);
  if (single_line) return fmt::format(" {}({})", name, fmt::join(signals, ", "));
  std::string out = fmt::format("\n{}(\n", name);
  for (std::size_t i = 0; i < signals.size(); ++i) {
    out += fmt::format("    {}{}\n", signals[i], i + 1 < signals.size() ? "," : "");
  }
  return out + ")";
}

std::string TimeText(std::int64_t time_us) {
  return fmt::format("{}{}.{:06}", time_us < 0 ? "-" : "", std::llabs(time_us) / 1000000,
                     std::llabs(time_us) % 1000000);
}

/// The record's time for JSON ("null" for a screen-format line without one) and CSV (empty).
std::string JsonTime(const protocol::CandumpRecord& r) {
  return r.has_time ? TimeText(r.time_us) : "null";
}
std::string CsvTime(const protocol::CandumpRecord& r) {
  return r.has_time ? TimeText(r.time_us) : std::string();
}

std::string CanIdText(const protocol::CanFrame& f) {
  return f.extended ? fmt::format("0x{:08X}", f.id) : fmt::format("0x{:03X}", f.id);
}

/// Counts of one decode run, reported on stderr at the end.
struct DecodeCounts {
  std::size_t frames = 0;  ///< lines that are frames (decoded or not)
  std::size_t decoded = 0, too_short = 0, bad_lines = 0;
  std::size_t unknown_standard = 0, unknown_extended = 0;  ///< IDs not in the DBC, 11 / 29 bit
  std::size_t error_frames = 0, remote_frames = 0;         ///< never decoded
  /// Of the unknown frames: a DBC message at CAN ID - n for a node n at or above the limit
  /// (below kHintMaxNode), and the largest such n.
  std::size_t unknown_per_pump = 0;
  unsigned max_node = 0;
};

/// Node IDs the hint looks at for unknown frames: a message at CAN ID - n, n below this.
constexpr unsigned kHintMaxNode = 128;

/// The smallest node n (limit <= n < kHintMaxNode) with a DBC message at the frame's ID - n, or
/// -1; remembered per ID (a log has few distinct IDs).
class NodeHint {
 public:
  NodeHint(const protocol::DbcCodec& codec, unsigned limit) : codec_(codec), limit_(limit) {}
  int Node(const protocol::CanFrame& f) {
    const std::uint64_t key = (static_cast<std::uint64_t>(f.extended) << 32) | f.id;
    if (const auto it = cache_.find(key); it != cache_.end()) return it->second;
    int node = -1;
    for (unsigned n = limit_; n < kHintMaxNode && n <= f.id; ++n) {
      if (codec_.Find(f.id - n, f.extended) >= 0) {
        node = static_cast<int>(n);
        break;
      }
    }
    cache_[key] = node;
    return node;
  }

 private:
  const protocol::DbcCodec& codec_;
  unsigned limit_;
  std::map<std::uint64_t, int> cache_;
};

/// Writes decoded frames as JSON lines, CSV rows, or the input annotated as cantools decode does.
class DecodeWriter {
 public:
  DecodeWriter(const Dbc& dbc, const DecodeOptions& o, std::vector<bool> wanted)
      : dbc_(dbc), o_(o), wanted_(std::move(wanted)), first_column_(dbc.messages.size(), 0) {}

  /// The CSV header: one column per signal of every selected message.
  void Header() {
    if (o_.format != "csv") return;
    std::string header = "time_s,interface,can_id,node,message";
    for (std::size_t i = 0; i < dbc_.messages.size(); ++i) {
      if (!wanted_[i]) continue;
      first_column_[i] = columns_;
      for (const auto& s : dbc_.messages[i].signals) {
        header += fmt::format(",{}.{}", dbc_.messages[i].name, s.name);
        ++columns_;
      }
    }
    fmt::print("{}\n", header);
  }

  bool Wanted(int index) const { return index >= 0 && wanted_[static_cast<std::size_t>(index)]; }

  /// A frame decoded into `values` (the message's signal order).
  void Frame(const protocol::CandumpRecord& r, const FrameMatch& m,
             const std::vector<double>& values) {
    const DbcMessage& msg = dbc_.messages[static_cast<std::size_t>(m.index)];
    if (o_.format == "csv") {
      std::vector<std::string> row(columns_);
      const std::size_t first = first_column_[static_cast<std::size_t>(m.index)];
      for (std::size_t i = 0; i < values.size(); ++i) row[first + i] = Number(values[i]);
      fmt::print("{},{},{},{},{},{}\n", CsvTime(r), r.interface, CanIdText(r.frame), m.node,
                 msg.name, fmt::join(row, ","));
      return;
    }
    std::string out = fmt::format(
        R"({{"time_s":{},"interface":"{}","can_id":"{}","node":{},"message":"{}","signals":{{)",
        JsonTime(r), JsonEscape(r.interface), CanIdText(r.frame), m.node, JsonEscape(msg.name));
    for (std::size_t i = 0; i < values.size(); ++i) {
      const std::string v = Number(values[i]);
      out += fmt::format(R"({}"{}":{})", i == 0 ? "" : ",", JsonEscape(msg.signals[i].name),
                         v.empty() ? "null" : v);
    }
    fmt::print("{}}}}}\n", out);
  }

 private:
  const Dbc& dbc_;
  const DecodeOptions& o_;
  std::vector<bool> wanted_;
  std::vector<std::size_t> first_column_;
  std::size_t columns_ = 0;
};

std::vector<bool> WantedMessages(const Dbc& dbc, const DecodeOptions& o) {
  std::vector<bool> wanted(dbc.messages.size(), o.messages.empty());
  for (const auto& name : o.messages) {
    const DbcMessage* m = dbc.FindMessage(name);
    if (m == nullptr)
      throw InputError(fmt::format("--message {}: no such message in {}", name, o.dbc_path));
    wanted[static_cast<std::size_t>(m - dbc.messages.data())] = true;
  }
  return wanted;
}

/// What one input line gives: a decoded frame, or why not (as cantools decode appends it).
enum class LineResult { kNotAFrame, kBadLine, kUnknownId, kNotWanted, kTooShort, kDecoded };

/// One parsed line against the DBC: its result, the message matched and the decoded values.
LineResult DecodeLine(const protocol::CandumpParse& p, const protocol::DbcCodec& codec,
                      const DecodeWriter& writer, unsigned node_id_limit, FrameMatch& match,
                      std::vector<double>& values) {
  if (p.skip) return LineResult::kNotAFrame;
  if (!p.ok) return LineResult::kBadLine;
  const protocol::CanFrame& f = p.record.frame;
  if (f.error || f.remote) return LineResult::kNotAFrame;
  match = MatchFrame(codec, f, node_id_limit);
  if (match.index < 0) return LineResult::kUnknownId;
  if (!writer.Wanted(match.index)) return LineResult::kNotWanted;
  const protocol::MessageCodec& mc = codec.message(static_cast<std::size_t>(match.index));
  values.resize(mc.signal_count());
  const auto payload = std::span<const std::uint8_t>(f.data.data(), f.len);
  return mc.Decode(payload, values) == protocol::CodecStatus::kOk ? LineResult::kDecoded
                                                                  : LineResult::kTooShort;
}

/// The text cantools decode appends to a line (empty for a line that is not a frame).
std::string Annotation(LineResult result, const protocol::CanFrame& f, const Dbc& dbc,
                       const FrameMatch& match, const std::vector<double>& values,
                       bool single_line) {
  switch (result) {
    case LineResult::kDecoded:
      return " ::" + CantoolsMessage(dbc.messages[static_cast<std::size_t>(match.index)],
                                     match.node, values, single_line);
    case LineResult::kUnknownId:
      return fmt::format(" :: Unknown frame id {0} (0x{0:x})", f.id);
    case LineResult::kTooShort:
      return fmt::format(" :: {}: {} bytes, shorter than the message",
                         dbc.messages[static_cast<std::size_t>(match.index)].name, f.len);
    default:
      return {};
  }
}

int Decode(const DecodeOptions& o) {
  const Dbc dbc = LoadDbc(o.dbc_path);
  const protocol::DbcCodec codec(dbc);
  DecodeWriter writer(dbc, o, WantedMessages(dbc, o));
  const bool annotate = o.format == "annotate";
  writer.Header();

  std::unique_ptr<std::ifstream> file;
  std::istream* in = &std::cin;
  const bool from_stdin = o.log_path.empty() || o.log_path == "-";
  const std::string log_name = from_stdin ? "<stdin>" : o.log_path;
  if (!from_stdin) {
    std::error_code ec;
    if (std::filesystem::is_directory(o.log_path, ec))
      throw InputError(fmt::format("{}: is a directory, not a candump log", o.log_path));
    file = std::make_unique<std::ifstream>(o.log_path);
    if (!*file) throw InputError(fmt::format("{}: cannot open", o.log_path));
    in = file.get();
  }

  std::vector<double> values;
  std::string line;
  std::size_t line_no = 0;
  DecodeCounts n;
  NodeHint hint(codec, o.node_id_limit);
  while (std::getline(*in, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const protocol::CandumpParse p = protocol::ParseCandumpLine(line);
    FrameMatch match;
    const LineResult result = DecodeLine(p, codec, writer, o.node_id_limit, match, values);
    if (result == LineResult::kBadLine && ++n.bad_lines <= kMaxReportedBadLines) {
      fmt::print(stderr, "{}:{}:{}: warning: {}; {}\n", log_name, line_no, p.column, p.error,
                 annotate ? "line passed through undecoded" : "line skipped");
    }
    if (result == LineResult::kUnknownId) {
      (p.record.frame.extended ? n.unknown_extended : n.unknown_standard) += 1;
      if (const int node = hint.Node(p.record.frame); node >= 0) {
        ++n.unknown_per_pump;
        n.max_node = std::max(n.max_node, static_cast<unsigned>(node));
      }
    }
    n.frames += p.ok;
    if (p.ok && p.record.frame.error) ++n.error_frames;
    if (p.ok && p.record.frame.remote) ++n.remote_frames;
    n.too_short += result == LineResult::kTooShort;
    n.decoded += result == LineResult::kDecoded;
    if (annotate) {
      fmt::print("{}{}\n", line,
                 Annotation(result, p.record.frame, dbc, match, values, o.single_line));
    } else if (result == LineResult::kDecoded) {
      writer.Frame(p.record, match, values);
    }
    // Live from a pipe (candump | pumptherm dbc decode): each line's result as it comes.
    if (from_stdin) std::fflush(stdout);
  }
  std::fflush(stdout);
  fmt::print(stderr,
             "{}: {} frames decoded, {} with IDs not in {} ({} 11-bit, {} 29-bit), {} shorter than "
             "their message, {} error and {} remote frames not decoded, {} bad lines {}\n",
             log_name, n.decoded, n.unknown_standard + n.unknown_extended, o.dbc_path,
             n.unknown_standard, n.unknown_extended, n.too_short, n.error_frames, n.remote_frames,
             n.bad_lines, annotate ? "passed through undecoded" : "skipped");
  if (n.unknown_per_pump > 0) {
    fmt::print(stderr,
               "{}: {} of the unknown frames are a message at CAN ID = DBC ID + node ID, node "
               "IDs up to {}: the DBC's IDs are per pump (or per node); decode them with "
               "--node-id-limit {}\n",
               log_name, n.unknown_per_pump, n.max_node, n.max_node + 1);
  }
  // A named file without a single frame is not a recording (a pipe may stay empty).
  if (!from_stdin && n.frames == 0) {
    fmt::print(stderr, "{}: no CAN frame in {} lines ({} not candump lines)\n", log_name, line_no,
               n.bad_lines);
    return 1;
  }
  return 0;
}

struct ExportOptions {
  std::string config;
  std::string output = "-";
  std::string interface;
  bool node_signals = false;
};

/// The messages of the mapping: those the gateway reads from the pumps (without the clear
/// command), the clear command, and those it sends.
struct MappedMessages {
  std::set<int> inputs, commands, outputs;
  int node_table = -1;  ///< the node-indexed message (node_index's), -1 if none
  int alarm = -1;       ///< alarm_node's message
  std::string node_index_signal, alarm_node_signal, node_temp_signal, node_sd_signal;
};

MappedMessages MappedOf(const protocol::SignalMapping& mapping) {
  using protocol::MappingInput;
  MappedMessages m;
  for (std::size_t i = 0; i < protocol::kMappingInputCount; ++i) {
    const auto& ref = mapping.inputs[i];
    if (!ref) continue;
    (static_cast<MappingInput>(i) == MappingInput::kAlarmClear ? m.commands : m.inputs)
        .insert(ref->message_index);
  }
  for (const auto& [key, ref] : mapping.outputs) m.outputs.insert(ref.message_index);
  for (const auto& [node, ref] : mapping.node_temperatures) m.outputs.insert(ref.message_index);
  auto signal = [&](std::string_view key, std::string& name) -> int {
    const protocol::SignalRef* ref = mapping.output(key);
    if (!ref) return -1;
    name = ref->signal;
    return ref->message_index;
  };
  m.node_table = signal(protocol::kNodeIndexKey, m.node_index_signal);
  m.alarm = signal("alarm_node", m.alarm_node_signal);
  signal(protocol::kNodeTempKey, m.node_temp_signal);
  signal(protocol::kNodeSdKey, m.node_sd_signal);
  return m;
}

/// "0 frame, 1 stator, 2 winding, 3 rotor".
std::string IndexedNodes(const std::vector<std::string>& names) {
  std::string out;
  for (std::size_t k = 0; k < names.size(); ++k)
    out += fmt::format("{}{} {}", k == 0 ? "" : ", ", k, names[k]);
  return out;
}

/// The node-indexed message with one signal per model node and quantity instead of the
/// multiplexed generic ones: winding_degC, winding_sd_K, ...
void NameNodeSignals(DbcMessage& m, const MappedMessages& mm,
                     const std::vector<std::string>& nodes) {
  std::vector<DbcSignal> signals;
  for (const DbcSignal& s : m.signals) {
    if (s.multiplexer_switch != mm.node_index_signal) {
      signals.push_back(s);
      continue;
    }
    for (std::size_t k = 0; k < nodes.size(); ++k) {
      DbcSignal named = s;
      named.name = s.name == mm.node_temp_signal ? nodes[k] + "_degC"
                   : s.name == mm.node_sd_signal ? nodes[k] + "_sd_K"
                                                 : nodes[k] + "_" + s.name;
      named.multiplexer_ranges = {{k, k}};
      named.comment = fmt::format("{} of node {} ({}): {}", s.name, k, nodes[k], s.comment);
      signals.push_back(std::move(named));
    }
  }
  m.signals = std::move(signals);
}

/// The gateway's heartbeat frame (daemon/frame_counter.cpp): uptime and frames received.
DbcMessage HeartbeatMessage(const daemon::DaemonConfig& c, const std::string& gateway) {
  DbcMessage m;
  m.id = c.gateway.heartbeat_id;
  m.name = "GW_HEARTBEAT";
  m.size_bytes = 8;
  m.transmitter = gateway;
  m.comment = fmt::format(
      "Heartbeat of gateway {}, every {} s on every interface it listens on (one ID for the "
      "whole gateway, gateway.heartbeat_id).",
      c.gateway.name, c.gateway.heartbeat_period_s);
  DbcSignal up;
  up.name = "Uptime_s";
  up.length_bits = 32;
  up.maximum = 4294967295.0;
  up.unit = "s";
  up.comment = "Seconds since the gateway started.";
  DbcSignal rx = up;
  rx.name = "FramesReceived";
  rx.start_bit = 32;
  rx.unit = "";
  rx.comment = "Frames received on all its interfaces since it started, modulo 2^32.";
  m.signals = {up, rx};
  m.attributes["GenMsgCycleTime"] = std::round(c.gateway.heartbeat_period_s * 1000.0);
  m.cycle_time_ms = c.gateway.heartbeat_period_s * 1000.0;
  return m;
}

/// The site's DBC: every mapped message once per pump of `iface`, at its CAN ID on the bus,
/// with the pump's model nodes named; the heartbeat; the base DBC's other messages.
Dbc SiteDbc(const daemon::Gateway& g, const Dbc& base, const protocol::SignalMapping& mapping,
            const std::string& iface, bool node_signals) {
  const daemon::DaemonConfig& c = g.config();
  const MappedMessages mm = MappedOf(mapping);
  const std::string gateway = c.gateway.name;
  Dbc site;
  site.version = fmt::format("pumptherm site {} {}", gateway, iface);
  site.value_tables = base.value_tables;
  site.attribute_definitions = base.attribute_definitions;
  site.network_attributes = base.network_attributes;
  site.comment = fmt::format(
      "Site DBC of pumptherm gateway {} on {}, written by pumptherm dbc export from {}: each "
      "message of {} once per pump at its CAN ID on this bus (DBC ID + node ID), named "
      "MESSAGE_PUMP; NodeIndex and AlarmNode name the pump's thermal-model nodes.",
      gateway, iface, c.source, base.file_name);
  // Nodes: the gateway, the pumps, and the base file's others (its drive and gateway nodes are
  // replaced by the pumps and this gateway).
  std::set<std::string> replaced;
  for (int mi : mm.inputs) replaced.insert(base.messages[static_cast<std::size_t>(mi)].transmitter);
  for (int mi : mm.outputs)
    replaced.insert(base.messages[static_cast<std::size_t>(mi)].transmitter);
  site.nodes.push_back(gateway);
  site.node_comments[gateway] = "The pumptherm gateway (pumpthermd).";
  std::set<std::pair<bool, std::uint32_t>> ids;
  std::set<int> mapped = mm.inputs;
  mapped.insert(mm.commands.begin(), mm.commands.end());
  mapped.insert(mm.outputs.begin(), mm.outputs.end());
  for (const auto& pump : g.pumps()) {
    const daemon::PumpConfig& pc = pump->config();
    if (pc.interface != iface) continue;
    const auto& nodes = pump->model().StateNames();
    site.nodes.push_back(pc.name);
    site.node_comments[pc.name] = fmt::format(
        "Pump {}: node ID {} on {}, motor {}, thermal model {} (nodes {}); frame sensor on {}.",
        pc.name, pc.node_id, pc.interface, pc.motor, pump->model().Name(), IndexedNodes(nodes),
        pc.measured_node);
    auto rename = [&](std::string& node, bool input) {
      if (!replaced.contains(node)) return;
      node = input ? pc.name : gateway;
    };
    for (int mi : mapped) {
      DbcMessage m = base.messages[static_cast<std::size_t>(mi)];
      const bool input = mm.inputs.contains(mi);
      m.id = mapping.CanId(base, mi, pc.node_id);
      m.name = fmt::format("{}_{}", m.name, pc.name);
      if (mm.inputs.contains(mi)) m.transmitter = pc.name;
      if (mm.outputs.contains(mi)) m.transmitter = gateway;
      for (auto& s : m.signals) {
        for (auto& r : s.receivers) rename(r, !input);
        if (mi == mm.alarm && s.name == mm.alarm_node_signal)
          for (std::size_t k = 0; k < nodes.size(); ++k)
            s.value_descriptions[static_cast<std::int64_t>(k)] = nodes[k];
        if (mi == mm.node_table && s.name == mm.node_index_signal)
          for (std::size_t k = 0; k < nodes.size(); ++k)
            s.value_descriptions[static_cast<std::int64_t>(k)] = nodes[k];
      }
      if (node_signals && mi == mm.node_table) NameNodeSignals(m, mm, nodes);
      m.comment = fmt::format("{} of pump {} (node {}): {}",
                              base.messages[static_cast<std::size_t>(mi)].name, pc.name, pc.node_id,
                              m.comment);
      const auto over = c.output_periods_s.find(base.messages[static_cast<std::size_t>(mi)].name);
      if (over != c.output_periods_s.end()) {
        m.attributes["GenMsgCycleTime"] = std::round(over->second * 1000.0);
        m.cycle_time_ms = over->second * 1000.0;
      }
      ids.insert({m.extended, m.id});
      site.messages.push_back(std::move(m));
    }
  }
  if (c.gateway.heartbeat_period_s > 0) {
    site.messages.push_back(HeartbeatMessage(c, gateway));
    ids.insert({false, c.gateway.heartbeat_id});
  }
  for (std::size_t mi = 0; mi < base.messages.size(); ++mi) {
    const DbcMessage& m = base.messages[mi];
    if (mapped.contains(static_cast<int>(mi)) || m.name == "GW_HEARTBEAT") continue;
    if (ids.contains({m.extended, m.id})) {
      fmt::print(stderr, "dbc export: {} of {} left out: its ID 0x{:X} is a pump's here\n", m.name,
                 base.file_name, m.id);
      continue;
    }
    site.messages.push_back(m);
  }
  for (const auto& n : base.nodes) {
    if (!replaced.contains(n)) site.nodes.push_back(n);
  }
  for (const auto& [n, text] : base.node_comments) {
    if (!replaced.contains(n)) site.node_comments[n] = text;
  }
  std::stable_sort(site.messages.begin(), site.messages.end(),
                   [](const DbcMessage& a, const DbcMessage& b) {
                     return std::pair(a.extended, a.id) < std::pair(b.extended, b.id);
                   });
  if (std::none_of(site.attribute_definitions.begin(), site.attribute_definitions.end(),
                   [](const auto& d) { return d.name == "GenMsgCycleTime"; })) {
    protocol::DbcAttributeDefinition d;
    d.name = "GenMsgCycleTime";
    d.object = protocol::DbcAttributeDefinition::Object::kMessage;
    d.type = protocol::DbcAttributeDefinition::Type::kInt;
    d.maximum = 65535;
    d.default_value = 0.0;
    site.attribute_definitions.push_back(d);
  }
  return site;
}

int Export(const ExportOptions& o) {
  daemon::DaemonConfig config;
  std::unique_ptr<daemon::Gateway> gateway;
  try {
    config = daemon::LoadConfig(o.config);
    gateway = std::make_unique<daemon::Gateway>(config);
  } catch (const daemon::ConfigError& e) {
    throw InputError(e.what());
  }
  std::string iface = o.interface;
  if (iface.empty()) {
    if (config.interfaces.size() > 1) {
      std::vector<std::string> names;
      for (const auto& i : config.interfaces) names.push_back(i.name);
      throw InputError(fmt::format("{} has {} buses ({}): a DBC describes one; give --interface",
                                   o.config, names.size(), fmt::join(names, ", ")));
    }
    iface = config.interfaces.empty() ? (config.pumps.empty() ? "" : config.pumps[0].interface)
                                      : config.interfaces[0].name;
  }
  if (std::none_of(config.pumps.begin(), config.pumps.end(),
                   [&](const auto& p) { return p.interface == iface; }))
    throw InputError(fmt::format("{}: no [[pump]] on '{}'", o.config, iface));
  const std::string dbc_path =
      daemon::ResolveResource(daemon::ResourceKind::kDbc, config.dbc.file, config.dbc.base_dir);
  const Dbc base = protocol::ParseDbc(daemon::ReadTextFile(dbc_path), dbc_path);
  const std::string mapping_path =
      daemon::ResolveResource(daemon::ResourceKind::kDbc, config.dbc.mapping, config.dbc.base_dir);
  const protocol::SignalMapping mapping = protocol::ParseMapping(
      daemon::ReadTextFile(mapping_path), mapping_path, base, daemon::MappingOutputs());
  const Dbc site = SiteDbc(*gateway, base, mapping, iface, o.node_signals);
  const std::string text = protocol::FormatDbc(site);
  if (o.output == "-") {
    std::fwrite(text.data(), 1, text.size(), stdout);
  } else {
    std::ofstream out(o.output, std::ios::binary);
    if (!(out << text) || !out.flush())
      throw std::runtime_error(fmt::format("{}: cannot write", o.output));
  }
  std::size_t pumps = 0;
  for (const auto& p : config.pumps) pumps += p.interface == iface;
  fmt::print(stderr,
             "{}: the site DBC of {} pump{} on {}: {} messages; decode its recordings with "
             "pumptherm dbc decode --dbc {} LOG (no --node-id-limit)\n",
             o.output == "-" ? "<stdout>" : o.output, pumps, pumps == 1 ? "" : "s", iface,
             site.messages.size(), o.output == "-" ? "SITE.dbc" : o.output);
  return 0;
}

const SubcommandRegistrar kDbcRegistrar{
    "dbc", "DBC files: check one, or decode a candump log with one",
    [](CLI::App& app) -> std::function<int()> {
      app.require_subcommand(1);
      app.footer(
          "Examples:\n"
          "  pumptherm dbc check protocol/pumptherm.dbc\n"
          "  candump -L vcan0 | pumptherm dbc decode --dbc protocol/pumptherm.dbc --node-id-limit "
          "16\n"
          "  candump -L vcan0 | pumptherm dbc decode --dbc pumptherm.dbc --format annotate -s\n"
          "  pumptherm dbc decode --dbc protocol/pumptherm.dbc --format csv recording.log > "
          "frames.csv");

      auto check_path = std::make_shared<std::string>();
      auto strict = std::make_shared<bool>(false);
      CLI::App* check = app.add_subcommand(
          "check", "Load a DBC file, list messages and signals, report problems");
      check->add_option("FILE", *check_path, "DBC file, or a shipped one by name (pumptherm.dbc)")
          ->required();
      check->add_flag("--strict", *strict,
                      "exit 2 if the file has problems (warnings) or no messages");
      check->footer(
          "Example: pumptherm dbc check protocol/pumptherm.dbc\n"
          "Warnings and errors name file:line:column. A malformed statement is a warning and\n"
          "is skipped (a BO_ with its signals, or one SG_); the rest of the file loads.");

      auto opts = std::make_shared<DecodeOptions>();
      CLI::App* decode = app.add_subcommand(
          "decode",
          "Decode a candump log (file or stdin) to JSON lines or CSV, one row per decoded frame");
      decode
          ->add_option("--dbc", opts->dbc_path,
                       "DBC file, or a shipped one by name (pumptherm.dbc)")
          ->required();
      decode->add_option("LOG", opts->log_path, "candump -l/-L log; stdin if absent or '-'");
      decode
          ->add_option(
              "--format", opts->format,
              "json (JSON lines, NaN as null), csv, or annotate (every input line echoed, a "
              "frame's decoded message appended after ' ::', as cantools decode prints it)")
          ->check(CLI::IsMember({"json", "csv", "annotate"}));
      decode->add_flag(
          "-s,--single-line", opts->single_line,
          "annotate: the decoded message on the frame's own line (cantools decode -s)");
      decode->add_option("--message", opts->messages, "decode only this message (repeatable)");
      decode
          ->add_option(
              "--node-id-limit", opts->node_id_limit,
              "match CAN ID = DBC ID + node ID for node IDs below this (pumptherm.dbc: 16)")
          ->check(CLI::Range(1u, 65536u));
      decode->footer(
          "Example: pumptherm dbc decode --dbc protocol/pumptherm.dbc --node-id-limit 16 run.log\n"
          "Signals a frame's multiplexer does not select, and 'not available' raw values, are "
          "empty\n"
          "(CSV) or null (JSON), left out or 'n/a' (annotate). Frames shorter than their message "
          "are\n"
          "counted and skipped; so are malformed log lines, with a file:line:column warning for "
          "each\n"
          "of the first 10 (annotate echoes them undecoded). Reading stdin, each line's output is\n"
          "flushed at once, so the command works at the end of a live pipe.");

      auto export_opts = std::make_shared<ExportOptions>();
      CLI::App* export_cmd = app.add_subcommand(
          "export",
          "Write the site's DBC from a daemon configuration: every message at its CAN ID on the "
          "bus, per pump, with the model's node names");
      export_cmd->add_option("--config", export_opts->config, "the daemon's configuration")
          ->required();
      export_cmd->add_option("-o,--output", export_opts->output, "DBC to write ('-' = stdout)")
          ->capture_default_str();
      export_cmd->add_option("--interface", export_opts->interface,
                             "the bus to describe, when the configuration has several");
      export_cmd->add_flag("--node-signals", export_opts->node_signals,
                           "one named signal per model node (winding_degC, winding_sd_K, ...) "
                           "in the node-indexed message, instead of NodeTemp_degC by NodeIndex");
      export_cmd->footer(
          "Each mapped message of the configuration's DBC is written once per pump, named\n"
          "MESSAGE_PUMP, at CAN ID = DBC ID + node ID; NodeIndex and AlarmNode carry value tables\n"
          "naming the pump's model nodes; the gateway's heartbeat (gateway.heartbeat_id) is "
          "added.\n"
          "Names longer than 32 characters or with other characters than letters, digits and\n"
          "'_' get a short name and their own as SystemMessageLongSymbol (cantools, canmatrix).\n"
          "Example: pumptherm dbc export --config /etc/pumptherm/pumpthermd.toml -o site.dbc");

      return [check, decode, export_cmd, check_path, strict, opts, export_opts]() -> int {
        if (check->parsed()) return Check(*check_path, *strict);
        if (decode->parsed()) return Decode(*opts);
        if (export_cmd->parsed()) return Export(*export_opts);
        return 2;
      };
    }};

}  // namespace
}  // namespace pumptherm::tools
