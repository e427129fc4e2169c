// pumptherm dbc check FILE            load a DBC, list its messages and signals, report problems
// pumptherm dbc decode --dbc FILE [LOG] candump log (file or stdin) -> JSON lines or CSV
#include <fmt/format.h>

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "protocol/candump_log.hpp"
#include "protocol/codec.hpp"
#include "protocol/dbc.hpp"
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
    fmt::print("{} {} {} bytes, {}, from {}\n", IdText(m), m.name, m.size_bytes, cycle, m.transmitter);
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
                         : s.is_signed                                          ? " signed"
                                                                                : " unsigned";
      fmt::print("  {} {}|{}@{}{} x{} {:+} [{}, {}] \"{}\"{}{}\n", s.name, s.start_bit, s.length_bits,
                 s.byte_order == ByteOrder::kLittleEndian ? 1 : 0, type, s.factor, s.offset,
                 s.minimum, s.maximum, s.unit,
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

/// 15 significant digits: raw * factor + offset without binary noise (308.4, not 308.40000000000003).
std::string Number(double v) { return std::isfinite(v) ? fmt::format("{:.15g}", v) : std::string(); }

/// Bad log lines warned about one by one; the rest are only counted.
constexpr std::size_t kMaxReportedBadLines = 10;

struct DecodeOptions {
  std::string dbc_path;
  std::string log_path;  // empty or "-": stdin
  std::string format = "json";
  std::vector<std::string> messages;
  unsigned node_id_limit = 1;
};

int Decode(const DecodeOptions& o) {
  const Dbc dbc = LoadDbc(o.dbc_path);
  const protocol::DbcCodec codec(dbc);
  std::vector<bool> wanted(dbc.messages.size(), o.messages.empty());
  for (const auto& name : o.messages) {
    const DbcMessage* m = dbc.FindMessage(name);
    if (m == nullptr) throw InputError(fmt::format("--message {}: no such message in {}", name, o.dbc_path));
    wanted[static_cast<std::size_t>(m - dbc.messages.data())] = true;
  }
  const bool csv = o.format == "csv";
  // CSV: one column per signal of every selected message; a row fills its own message's columns.
  std::vector<std::size_t> first_column(dbc.messages.size(), 0);
  std::size_t columns = 0;
  if (csv) {
    std::string header = "time_s,interface,can_id,node,message";
    for (std::size_t i = 0; i < dbc.messages.size(); ++i) {
      if (!wanted[i]) continue;
      first_column[i] = columns;
      for (const auto& s : dbc.messages[i].signals) {
        header += fmt::format(",{}.{}", dbc.messages[i].name, s.name);
        ++columns;
      }
    }
    fmt::print("{}\n", header);
  }

  std::unique_ptr<std::ifstream> file;
  std::istream* in = &std::cin;
  const std::string log_name = o.log_path.empty() || o.log_path == "-" ? "<stdin>" : o.log_path;
  if (log_name != "<stdin>") {
    file = std::make_unique<std::ifstream>(o.log_path);
    if (!*file) throw InputError(fmt::format("{}: cannot open", o.log_path));
    in = file.get();
  }

  std::vector<double> values;
  std::vector<std::string> row(columns);
  std::string line;
  std::size_t line_no = 0, decoded = 0, unknown = 0, too_short = 0, bad_lines = 0;
  while (std::getline(*in, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const protocol::CandumpParse p = protocol::ParseCandumpLine(line);
    if (p.skip) continue;
    if (!p.ok) {
      if (++bad_lines <= kMaxReportedBadLines) {
        fmt::print(stderr, "{}:{}:{}: warning: {}; line skipped\n", log_name, line_no, p.column, p.error);
      }
      continue;
    }
    const protocol::CanFrame& f = p.record.frame;
    if (f.error || f.remote) continue;
    int index = -1;
    unsigned node = 0;
    for (; node < o.node_id_limit && node <= f.id; ++node) {
      index = codec.Find(f.id - node, f.extended);
      if (index >= 0) break;
    }
    if (index < 0 || !wanted[static_cast<std::size_t>(index)]) {
      if (index < 0) ++unknown;
      continue;
    }
    const DbcMessage& m = dbc.messages[static_cast<std::size_t>(index)];
    const protocol::MessageCodec& mc = codec.message(static_cast<std::size_t>(index));
    values.resize(mc.signal_count());
    if (mc.Decode(std::span<const std::uint8_t>(f.data.data(), f.len), values) != protocol::CodecStatus::kOk) {
      ++too_short;
      continue;
    }
    ++decoded;
    const std::string time_s = fmt::format("{}{}.{:06}", p.record.time_us < 0 ? "-" : "",
                                           std::llabs(p.record.time_us) / 1000000,
                                           std::llabs(p.record.time_us) % 1000000);
    const std::string can_id = f.extended ? fmt::format("0x{:08X}", f.id) : fmt::format("0x{:03X}", f.id);
    if (csv) {
      std::fill(row.begin(), row.end(), std::string());
      for (std::size_t i = 0; i < values.size(); ++i) row[first_column[static_cast<std::size_t>(index)] + i] = Number(values[i]);
      std::string out = fmt::format("{},{},{},{},{}", time_s, p.record.interface, can_id, node, m.name);
      for (const auto& cell : row) {
        out += ',';
        out += cell;
      }
      fmt::print("{}\n", out);
    } else {
      std::string out = fmt::format(R"({{"time_s":{},"interface":"{}","can_id":"{}","node":{},"message":"{}","signals":{{)",
                                    time_s, JsonEscape(p.record.interface), can_id, node, JsonEscape(m.name));
      for (std::size_t i = 0; i < values.size(); ++i) {
        const std::string v = Number(values[i]);
        out += fmt::format(R"({}"{}":{})", i == 0 ? "" : ",", JsonEscape(m.signals[i].name), v.empty() ? "null" : v);
      }
      fmt::print("{}}}}}\n", out);
    }
  }
  std::fflush(stdout);
  fmt::print(stderr,
             "{}: {} frames decoded, {} with IDs not in {}, {} shorter than their message, {} bad "
             "lines skipped\n",
             log_name, decoded, unknown, o.dbc_path, too_short, bad_lines);
  return 0;
}

const SubcommandRegistrar kRegistrar{
    "dbc", "DBC files: check one, or decode a candump log with one",
    [](CLI::App& app) -> std::function<int()> {
      app.require_subcommand(1);
      app.footer(
          "Examples:\n"
          "  pumptherm dbc check protocol/pumptherm.dbc\n"
          "  candump -L vcan0 | pumptherm dbc decode --dbc protocol/pumptherm.dbc --node-id-limit 16\n"
          "  pumptherm dbc decode --dbc protocol/pumptherm.dbc --format csv recording.log > frames.csv");

      auto check_path = std::make_shared<std::string>();
      auto strict = std::make_shared<bool>(false);
      CLI::App* check = app.add_subcommand("check", "Load a DBC file, list messages and signals, report problems");
      check->add_option("FILE", *check_path, "DBC file, or a shipped one by name (pumptherm.dbc)")->required();
      check->add_flag("--strict", *strict, "exit 2 if the file has problems (warnings) or no messages");
      check->footer("Example: pumptherm dbc check protocol/pumptherm.dbc\n"
                    "Warnings and errors name file:line:column. A malformed statement is a warning and\n"
                    "is skipped (a BO_ with its signals, or one SG_); the rest of the file loads.");

      auto opts = std::make_shared<DecodeOptions>();
      CLI::App* decode = app.add_subcommand(
          "decode", "Decode a candump log (file or stdin) to JSON lines or CSV, one row per decoded frame");
      decode->add_option("--dbc", opts->dbc_path, "DBC file, or a shipped one by name (pumptherm.dbc)")->required();
      decode->add_option("LOG", opts->log_path, "candump -l/-L log; stdin if absent or '-'");
      decode->add_option("--format", opts->format, "json (JSON lines, NaN as null) or csv")
          ->check(CLI::IsMember({"json", "csv"}));
      decode->add_option("--message", opts->messages, "decode only this message (repeatable)");
      decode->add_option("--node-id-limit", opts->node_id_limit,
                         "match CAN ID = DBC ID + node ID for node IDs below this (pumptherm.dbc: 16)")
          ->check(CLI::Range(1u, 65536u));
      decode->footer(
          "Example: pumptherm dbc decode --dbc protocol/pumptherm.dbc --node-id-limit 16 run.log\n"
          "Signals a frame's multiplexer does not select, and 'not available' raw values, are empty\n"
          "(CSV) or null (JSON). Frames shorter than their message are counted and skipped; so are\n"
          "malformed log lines, with a file:line:column warning for each of the first 10.");

      return [check, decode, check_path, strict, opts]() -> int {
        if (check->parsed()) return Check(*check_path, *strict);
        if (decode->parsed()) return Decode(*opts);
        return 2;
      };
    }};

}  // namespace
}  // namespace pumptherm::tools
