#include "tools/pumptherm/recording.hpp"

#include <fmt/core.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <sstream>
#include <vector>

#include "estimators/motor.hpp"
#include "protocol/candump_log.hpp"
#include "protocol/codec.hpp"
#include "protocol/dbc.hpp"
#include "protocol/dq_pairing.hpp"
#include "protocol/mapping.hpp"
#include "shipped/shipped_files.hpp"
#include "tools/pumptherm/model_files.hpp"
#include "tools/pumptherm/subcommand.hpp"

namespace pumptherm::tools {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr std::uint64_t kWarnedLines = 5;

using protocol::MappingInput;

std::string Load(shipped::FileKind kind, const std::string& reference, const char* what) {
  try {
    return shipped::ReadTextFile(shipped::Resolve(kind, reference));
  } catch (const std::exception& e) {
    throw InputError(fmt::format("--{}: {}", what, e.what()));
  }
}

/// Decoding state of one pump's telemetry: the halves paired as the daemon pairs them
/// (protocol::DqPairing), the latest speed and status values.
class Assembler {
 public:
  /// `status_mapped`: the mapping has the status message's temperatures (rows wait for them).
  Assembler(const estimators::MotorDescription& motor, bool status_mapped, std::ostringstream& csv,
            RecordingCounts& counts)
      : motor_(motor), status_mapped_(status_mapped), csv_(csv), counts_(counts) {}

  /// `v` holds this frame's mapped inputs (NaN where the frame has none).
  void OnFrame(std::int64_t t_us, const double* v, bool currents, bool voltages, bool status) {
    auto at = [&](MappingInput i) { return v[static_cast<std::size_t>(i)]; };
    if (status) {
      if (std::isfinite(at(MappingInput::kSpeedMechRpm)))
        speed_rpm_ = at(MappingInput::kSpeedMechRpm);
      if (std::isfinite(at(MappingInput::kFrameSensorDegC)))
        frame_C_ = at(MappingInput::kFrameSensorDegC);
      if (std::isfinite(at(MappingInput::kAmbientDegC)))
        ambient_C_ = at(MappingInput::kAmbientDegC);
    }
    const double counter = at(MappingInput::kRollingCounter);
    protocol::DqPair pair;
    bool paired = false;
    if (currents) {
      if (std::isfinite(at(MappingInput::kSpeedElecRadPerS)))
        speed_rpm_ = estimators::MechanicalSpeed_rpm(motor_, at(MappingInput::kSpeedElecRadPerS));
      paired = pairing_.OnCurrents(t_us, at(MappingInput::kIdA), at(MappingInput::kIqA), counter,
                                   pair) ||
               paired;
    }
    if (voltages) {
      paired = pairing_.OnVoltages(t_us, at(MappingInput::kUdV), at(MappingInput::kUqV), counter,
                                   pair) ||
               paired;
    }
    counts_.unpaired = pairing_.unpaired();
    if (paired) Row(pair);
  }

 private:
  void Row(const protocol::DqPair& p) {
    const bool finite = std::isfinite(p.id_A) && std::isfinite(p.iq_A) && std::isfinite(p.ud_V) &&
                        std::isfinite(p.uq_V) && std::isfinite(speed_rpm_);
    // Rows start once the status frame has given the temperatures, so that every cell is a number.
    const bool temperatures =
        !status_mapped_ || (std::isfinite(frame_C_) && std::isfinite(ambient_C_));
    if (!finite || !temperatures) return;
    if (counts_.first_us < 0) counts_.first_us = p.t_us;
    // Ten significant digits: a decoded value is raw * factor + offset, whose last binary
    // digits (21.700000000000003 for 217 * 0.1) are not information; time to the microsecond.
    csv_ << fmt::format("{:.12g},{:.10g},{:.10g},{:.10g},{:.10g},{:.10g},{:.10g},{:.10g}\n",
                        static_cast<double>(p.t_us - counts_.first_us) * 1e-6, p.id_A, p.iq_A,
                        p.ud_V, p.uq_V, speed_rpm_, frame_C_, ambient_C_);
    ++counts_.rows;
  }

  const estimators::MotorDescription& motor_;
  bool status_mapped_;
  std::ostringstream& csv_;
  RecordingCounts& counts_;
  protocol::DqPairing pairing_;
  double speed_rpm_ = kNaN, frame_C_ = kNaN, ambient_C_ = kNaN;
};

}  // namespace

void AddRecordingOptions(CLI::App& app, RecordingSource& s) {
  app.add_option("--log", s.log,
                 "candump log (-l/-L format) to read the pump's telemetry from ('-' = stdin)");
  app.add_option("--node-id", s.node_id,
                 "with --log: the pump's node ID (CAN ID = DBC ID + node ID)")
      ->capture_default_str();
  app.add_option("--interface", s.interface,
                 "with --log: only frames of this interface (default: any)");
  app.add_option("--dbc", s.dbc, "with --log: DBC file or shipped name")->capture_default_str();
  app.add_option("--mapping", s.mapping, "with --log: signal mapping file or shipped name")
      ->capture_default_str();
}

std::string RecordingToCsv(const RecordingSource& s, RecordingCounts* out_counts) {
  RecordingCounts local;
  RecordingCounts& counts = out_counts ? *out_counts : local;
  protocol::Dbc dbc;
  protocol::SignalMapping mapping;
  try {
    dbc = protocol::ParseDbc(Load(shipped::FileKind::kDbc, s.dbc, "dbc"), s.dbc);
    mapping = protocol::ParseMapping(Load(shipped::FileKind::kDbc, s.mapping, "mapping"), s.mapping,
                                     dbc, {});
  } catch (const std::exception& e) {
    throw InputError(e.what());
  }
  if (s.node_id >= mapping.node_id_limit) {
    throw InputError(fmt::format("--node-id {} is not below the mapping's node_id_limit {}",
                                 s.node_id, mapping.node_id_limit));
  }
  const estimators::MotorDescription motor = LoadMotor(s.motor);
  const protocol::DbcCodec codec(dbc);
  // Per DBC message: which inputs it carries (signal index, scale, offset).
  struct Bound {
    MappingInput input;
    int signal;
    double scale, offset;
  };
  std::vector<std::vector<Bound>> bound(dbc.messages.size());
  for (std::size_t i = 0; i < protocol::kMappingInputCount; ++i) {
    const auto& ref = mapping.inputs[i];
    if (ref) {
      bound[static_cast<std::size_t>(ref->message_index)].push_back(
          {static_cast<MappingInput>(i), ref->signal_index, ref->scale, ref->offset});
    }
  }
  std::ifstream file;
  if (s.log != "-") {
    std::error_code ec;
    if (std::filesystem::is_directory(s.log, ec))
      throw InputError(fmt::format("--log {}: is a directory, not a candump log", s.log));
    file.open(s.log);
    if (!file) throw InputError(fmt::format("--log {}: cannot open", s.log));
  }
  std::istream& in = s.log == "-" ? std::cin : file;
  const std::string where = s.log == "-" ? "<stdin>" : s.log;
  std::ostringstream csv;
  csv << "time_s,id_A,iq_A,ud_V,uq_V,speed_rpm,frame_degC,ambient_degC\n";
  const bool status_mapped = mapping.input(MappingInput::kFrameSensorDegC).has_value() &&
                             mapping.input(MappingInput::kAmbientDegC).has_value();
  Assembler assembler(motor, status_mapped, csv, counts);
  std::vector<double> values(64);
  // The stamps' time base (Unix time, or candump -t z / -t d), from the first ones, as the
  // daemon reads a recording (protocol::ClassifyCandumpStamps).
  std::vector<std::string> held;
  std::vector<std::int64_t> stamps;
  std::string line;
  while (stamps.size() < protocol::kCandumpStampsToClassify && std::getline(in, line)) {
    const protocol::CandumpParse p = protocol::ParseCandumpLine(line);
    if (p.ok && p.record.has_time) stamps.push_back(p.record.time_us);
    held.push_back(std::move(line));
  }
  protocol::CandumpTimeline timeline(protocol::ClassifyCandumpStamps(stamps.data(), stamps.size()));
  if (timeline.base() != protocol::CandumpTimeBase::kAbsolute) {
    fmt::print(stderr,
               "{}: the timestamps are {}, not Unix time: read as seconds since the start\n", where,
               protocol::CandumpTimeBaseName(timeline.base()));
  }
  std::size_t next_held = 0;
  auto next_line = [&]() -> bool {
    if (next_held < held.size()) {
      line = std::move(held[next_held++]);
      return true;
    }
    return static_cast<bool>(std::getline(in, line));
  };
  while (next_line()) {
    ++counts.lines;
    const protocol::CandumpParse p = protocol::ParseCandumpLine(line);
    if (p.skip) continue;
    if (!p.ok) {
      if (++counts.bad_lines <= kWarnedLines) {
        fmt::print(stderr, "{}:{}:{}: skipped: {}\n", where, counts.lines, p.column, p.error);
      }
      continue;
    }
    if (!p.record.has_time) {
      if (++counts.untimed_lines <= kWarnedLines) {
        fmt::print(
            stderr,
            "{}:{}: skipped: no timestamp (candump's screen format without -t a); record with "
            "candump -l, -L or -t a\n",
            where, counts.lines);
      }
      continue;
    }
    const std::int64_t time_us = timeline.TimeUs(p.record.time_us);
    const protocol::CanFrame& f = p.record.frame;
    if (f.error || f.remote || f.id < s.node_id) continue;
    if (!s.interface.empty() && p.record.interface != s.interface) continue;
    const int m = codec.Find(f.id - s.node_id, f.extended);
    if (m < 0 || bound[static_cast<std::size_t>(m)].empty()) continue;
    ++counts.frames;
    const auto& mc = codec.message(static_cast<std::size_t>(m));
    if (values.size() < mc.signal_count()) values.resize(mc.signal_count());
    if (mc.Decode(std::span<const std::uint8_t>(f.data.data(), f.len), values) !=
        protocol::CodecStatus::kOk) {
      ++counts.undecodable;
      continue;
    }
    double v[protocol::kMappingInputCount];
    for (double& x : v) x = kNaN;
    bool currents = false, voltages = false, status = false;
    for (const Bound& b : bound[static_cast<std::size_t>(m)]) {
      v[static_cast<std::size_t>(b.input)] =
          b.scale * values[static_cast<std::size_t>(b.signal)] + b.offset;
      currents = currents || b.input == MappingInput::kIqA;
      voltages = voltages || b.input == MappingInput::kUqV;
      status = status || b.input == MappingInput::kFrameSensorDegC ||
               b.input == MappingInput::kSpeedMechRpm;
    }
    assembler.OnFrame(time_us, v, currents, voltages, status);
  }
  if (counts.bad_lines > kWarnedLines) {
    fmt::print(stderr, "{}: {} bad lines skipped in all (the first {} shown)\n", where,
               counts.bad_lines, kWarnedLines);
  }
  if (counts.untimed_lines > kWarnedLines) {
    fmt::print(stderr, "{}: {} lines without a timestamp skipped in all (the first {} shown)\n",
               where, counts.untimed_lines, kWarnedLines);
  }
  if (counts.rows == 0) {
    throw InputError(fmt::format(
        "{}: no paired current and voltage frames of node ID {}{} ({} lines, {} of its frames)",
        where, s.node_id, s.interface.empty() ? "" : " on " + s.interface, counts.lines,
        counts.frames));
  }
  return csv.str();
}

}  // namespace pumptherm::tools
