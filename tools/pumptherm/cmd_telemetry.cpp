// pumptherm telemetry: one pump's drive telemetry from a candump recording, as the CSV that
// `identify` and `estimate` read (they also take --log directly).
#include <fmt/core.h>

#include <cstdio>
#include <fstream>

#include "tools/pumptherm/recording.hpp"
#include "tools/pumptherm/subcommand.hpp"

namespace pumptherm::tools {
namespace {

struct TelemetryOptions {
  RecordingSource source;
  std::string output = "-";
};

int RunTelemetry(const TelemetryOptions& o) {
  if (o.source.log.empty()) throw InputError("--log is required");
  RecordingCounts counts;
  const std::string csv = RecordingToCsv(o.source, &counts);
  if (o.output == "-") {
    std::fwrite(csv.data(), 1, csv.size(), stdout);
  } else {
    std::ofstream out(o.output);
    if (!(out << csv)) throw std::runtime_error(fmt::format("{}: cannot write", o.output));
  }
  fmt::print(stderr,
             "telemetry: {} rows from {} frames of node ID {} ({} lines, {} bad, {} without a "
             "timestamp, {} "
             "undecodable, {} unpaired); time_s 0 is Unix time {:.6f}\n",
             counts.rows, counts.frames, o.source.node_id, counts.lines, counts.bad_lines,
             counts.untimed_lines, counts.undecodable, counts.unpaired,
             static_cast<double>(counts.first_us) * 1e-6);
  return 0;
}

const SubcommandRegistrar kTelemetryRegistrar{
    "telemetry",
    "one pump's dq telemetry from a candump recording, as identify's and estimate's CSV",
    [](CLI::App& app) {
      auto o = std::make_shared<TelemetryOptions>();
      AddRecordingOptions(app, o->source);
      app.add_option("--motor", o->source.motor, "motor preset or file (pole pairs for the speed)")
          ->capture_default_str();
      app.add_option("--output,-o", o->output, "CSV to write ('-' = stdout)")
          ->capture_default_str();
      app.footer(
          "Columns: time_s (from the first row), id_A, iq_A, ud_V, uq_V, speed_rpm, frame_degC, "
          "ambient_degC.\n"
          "Example:\n"
          "  pumptherm telemetry --log demo.log --node-id 3 -o pump3.csv\n"
          "  pumptherm identify --log demo.log --node-id 3 -o rs.csv     (the same, in one step)");
      return [o] { return RunTelemetry(*o); };
    }};

}  // namespace
}  // namespace pumptherm::tools
