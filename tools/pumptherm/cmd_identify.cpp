// `pumptherm identify`: stator resistance, flux and winding temperature from dq telemetry
// (estimators/resistance_identifier.hpp; docs/resistance-identification.md); with --model, the
// daemon's fused estimator over a recording instead (the winding from the voltages).
#include <fmt/core.h>
#include <fmt/format.h>
#include <stdlib.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "estimators/motor.hpp"
#include "estimators/resistance_identifier.hpp"
#include "tools/common/csv.hpp"
#include "tools/pumptherm/model_files.hpp"
#include "tools/pumptherm/recording.hpp"
#include "tools/pumptherm/recording_pump.hpp"
#include "tools/pumptherm/subcommand.hpp"

namespace pumptherm::tools {
namespace {

namespace est = pumptherm::estimators;

int Run(const std::string& input, const RecordingSource& recording, const std::string& output,
        const std::string& motor_arg, int block_samples, double min_current_A) {
  const est::MotorDescription motor = LoadMotor(motor_arg);
  std::vector<double> t, id, iq, ud, uq, rpm;
  try {
    if (input.empty() == recording.log.empty())
      throw InputError("give --input CSV or --log RECORDING");
    RecordingSource source = recording;
    source.motor = motor_arg;
    const CsvTable table = input.empty()
                               ? CsvTable::Parse(RecordingToCsv(source, nullptr), recording.log)
                               : CsvTable::Read(input);
    t = table.Time("time_s");
    id = table.Column("id_A");
    iq = table.Column("iq_A");
    ud = table.Column("ud_V");
    uq = table.Column("uq_V");
    rpm = table.Column("speed_rpm");
  } catch (const CsvError& e) {
    throw InputError(e.what());
  }
  if (t.empty()) throw InputError(fmt::format("{}: no data rows", input));

  est::ResistanceIdentifierConfig config;
  config.block_samples = block_samples;
  config.min_current_A = min_current_A;
  est::ResistanceIdentifier identifier(motor, config);
  // Column names as the daemon's CSV names the same quantities (docs/daemon.md, "Names").
  CsvWriter out(output, {"time_s", "resistance_ohm", "flux_Wb", "winding_resistance_degC", "status",
                         "winding_resistance_sd_K", "flux_sd_Wb"});
  // The first sample's period is taken from the second (the data give no earlier time).
  const double first_dt = t.size() > 1 ? t[1] - t[0] : 0.0;
  for (std::size_t k = 0; k < t.size(); ++k) {
    const double dt = k == 0 ? first_dt : t[k] - t[k - 1];
    const est::ResistanceEstimate e = identifier.Update(
        {id[k], iq[k], ud[k], uq[k], est::ElectricalSpeed_rad_per_s(motor, rpm[k])}, dt);
    out.Row({t[k], e.resistance_ohm, e.flux_Wb, e.winding_degC,
             static_cast<double>(static_cast<int>(e.status)), e.winding_sd_K, e.flux_sd_Wb});
  }
  out.Close();
  const est::ResistanceEstimate& last = identifier.estimate();
  fmt::print(stderr,
             "identify: {} rows; last: Rs {:.6f} ohm, psi_f {:.7f} Wb, winding {:.2f} degC "
             "(1-sigma {:.2f} K), {}\n",
             t.size(), last.resistance_ohm, last.flux_Wb, last.winding_degC, last.winding_sd_K,
             est::ToString(last.status));
  return 0;
}

// ---------------------------------------------------------------------------------------------
// --model: the daemon's fused estimator (the disturbance-state filter with the voltage row) over
// a recording, one pump, through the same Gateway path as `pumptherm estimate --log`.

struct Options {
  std::string input, output = "-", motor = "han2019-tmp";
  RecordingSource recording;
  int block_samples = 100;
  double min_current_A = 0.0;
  std::string model, config, pump;       ///< --model, or --config with --pump: the fused estimator
  std::vector<CLI::Option*> paper_only;  ///< options of the DFRLS identifier alone
  CLI::Option* motor_option = nullptr;
};

/// The columns of the daemon's CSV that `identify --model` writes, in this order: the fused
/// estimate and its identification status, then the DFRLS identifier's own winding (NaN unless it
/// is tracking) and its status.
const std::vector<std::string> kFusedColumns{"time_s",
                                             "winding_resistance_degC",
                                             "winding_resistance_sd_K",
                                             "magnet_flux_degC",
                                             "magnet_flux_sd_K",
                                             "voltage_reading",
                                             "ident_status",
                                             "r0_error",
                                             "psi0_error",
                                             "voltage_offset_V",
                                             "identifier_winding_degC",
                                             "identifier_status"};

/// A file in the temporary folder, removed when this goes out of scope.
struct TemporaryFile {
  std::string path;
  TemporaryFile() {
    std::string pattern =
        (std::filesystem::temp_directory_path() / "pumptherm-identify-XXXXXX").string();
    const int fd = mkstemp(pattern.data());
    if (fd < 0)
      throw std::runtime_error(fmt::format("{}: cannot create: {}", pattern, std::strerror(errno)));
    ::close(fd);
    path = pattern;
  }
  ~TemporaryFile() {
    std::error_code ignored;
    std::filesystem::remove(path, ignored);
  }
  TemporaryFile(const TemporaryFile&) = delete;
  TemporaryFile& operator=(const TemporaryFile&) = delete;
};

/// The last finite value of `v` and its row, or row -1.
std::ptrdiff_t LastFinite(const std::vector<double>& v) {
  for (std::size_t k = v.size(); k-- > 0;)
    if (std::isfinite(v[k])) return static_cast<std::ptrdiff_t>(k);
  return -1;
}

double Percent(std::size_t part, std::size_t whole) {
  return whole == 0 ? 0.0 : 100.0 * static_cast<double>(part) / static_cast<double>(whole);
}

/// The summary on stderr: how much of the time the winding from resistance was published, its
/// last value and sd, and R0 and psi0 against the motor's nameplate.
void PrintFusedSummary(const CsvTable& csv, const est::MotorDescription& motor,
                       const std::string& model) {
  const std::vector<double> t = csv.Time("time_s");
  const std::vector<double> w = csv.ColumnAllowingNaN("winding_resistance_degC");
  const std::vector<double> w_sd = csv.ColumnAllowingNaN("winding_resistance_sd_K");
  const std::vector<std::string> reading = csv.Text("voltage_reading");
  const std::vector<double> paper = csv.ColumnAllowingNaN("identifier_winding_degC");
  double total_s = 0.0, published_s = 0.0;
  std::size_t fused = 0, paper_rows = 0;
  for (std::size_t k = 0; k < t.size(); ++k) {
    if (reading[k] == "fused") ++fused;
    if (std::isfinite(paper[k])) ++paper_rows;
    if (k == 0) continue;
    total_s += t[k] - t[k - 1];
    if (std::isfinite(w[k])) published_s += t[k] - t[k - 1];
  }
  fmt::print(stderr,
             "identify, the daemon's estimator (model {}): {} rows over {:.0f} s; winding "
             "from resistance published {:.1f} % of the time; voltage row fused in {:.1f} % "
             "of the rows; the DFRLS identifier's own winding (tracking) in {:.1f} %\n",
             model, t.size(), total_s, total_s > 0.0 ? 100.0 * published_s / total_s : 0.0,
             Percent(fused, t.size()), Percent(paper_rows, t.size()));
  const std::ptrdiff_t last = LastFinite(w);
  if (last < 0) {
    fmt::print(stderr, "  winding from resistance: never published\n");
  } else {
    const auto k = static_cast<std::size_t>(last);
    fmt::print(stderr, "  winding from resistance: last {:.2f} degC (sd {:.2f} K) at time_s {}{}\n",
               w[k], w_sd[k], t[k], k + 1 == t.size() ? "" : " (not published at the end)");
  }
  const std::vector<double> dr = csv.ColumnAllowingNaN("r0_error");
  const std::vector<double> dpsi = csv.ColumnAllowingNaN("psi0_error");
  const double r0 = motor.copper.r0_ohm, psi0 = motor.flux_Wb;
  if (t.empty() || !std::isfinite(dr.back()) || !std::isfinite(dpsi.back())) {
    fmt::print(stderr,
               "  R0, psi0: not estimated (no voltage row); nameplate {:.5f} ohm, {:.6f} Wb\n", r0,
               psi0);
    return;
  }
  fmt::print(stderr,
             "  R0 {:.5f} ohm at {:.1f} degC (nameplate {:.5f}, {:+.2f} %), psi0 {:.6f} Wb "
             "(nameplate {:.6f}, {:+.3f} %)\n",
             r0 * (1.0 + dr.back()), motor.copper.t0_degC, r0, 100.0 * dr.back(),
             psi0 * (1.0 + dpsi.back()), psi0, 100.0 * dpsi.back());
}

int RunFused(const Options& opt) {
  if (opt.recording.log.empty() || !opt.input.empty()) {
    throw InputError(
        "--model and --config run the daemon's estimator on a candump recording: give --log "
        "RECORDING (a CSV of dq samples has no frame temperature, ambient or timing the "
        "daemon would see; without --model identify runs the paper's DFRLS on --input)");
  }
  if (opt.config.empty() != opt.pump.empty()) throw InputError("--config and --pump go together");
  if (!opt.config.empty() && !opt.model.empty()) {
    throw InputError(
        "--model with --config: the configuration's [[pump]] names its thermal_model (give one "
        "of them)");
  }
  if (!opt.config.empty() && opt.motor_option->count() > 0)
    throw InputError("--motor with --config: the configuration's [[pump]] names its motor");
  for (const CLI::Option* option : opt.paper_only) {
    if (option->count() > 0) {
      throw InputError(fmt::format(
          "{} is for the paper's DFRLS (without --model the daemon's own settings apply)",
          option->get_name()));
    }
  }
  PumpRecordingRun run;
  run.tool = "pumptherm identify";
  run.config = opt.config;
  run.config_pump = opt.pump;
  run.pump.name = "pump";
  run.pump.thermal_model = opt.model;
  run.pump.motor = opt.motor;
  run.pump.node_id = opt.recording.node_id;
  run.recording = opt.recording;
  const TemporaryFile daemon_csv;
  run.csv_file = daemon_csv.path;
  const PumpRecordingResult ran = RunPumpOnRecording(run);
  try {
    const CsvTable csv = CsvTable::Read(daemon_csv.path);
    std::vector<std::vector<std::string>> columns;
    for (const auto& name : kFusedColumns) columns.push_back(csv.Text(name));
    CsvWriter out(opt.output, kFusedColumns);
    std::vector<std::string> row(kFusedColumns.size());
    for (std::size_t k = 0; k < csv.rows(); ++k) {
      for (std::size_t c = 0; c < columns.size(); ++c) row[c] = columns[c][k];
      out.Row({}, row);
    }
    out.Close();
    PrintFusedSummary(csv, ran.motor,
                      opt.config.empty() ? opt.model : ran.config.pumps.front().thermal_model);
  } catch (const CsvError& e) {
    throw std::runtime_error(fmt::format("the daemon's CSV: {}", e.what()));
  }
  return 0;
}

const SubcommandRegistrar kIdentifyRegistrar{
    "identify", "stator resistance, flux and winding temperature from dq telemetry",
    [](CLI::App& app) {
      auto opt = std::make_shared<Options>();
      app.add_option("--input,-i", opt->input,
                     "CSV with columns time_s, id_A, iq_A, ud_V, uq_V, speed_rpm (mechanical "
                     "r/min), any order; '-' reads standard input (or --log)");
      AddRecordingOptions(app, opt->recording);
      app.add_option(
             "--output,-o", opt->output,
             "CSV written with time_s, resistance_ohm, flux_Wb, winding_resistance_degC, status, "
             "winding_resistance_sd_K, flux_sd_Wb (with --model: time_s, "
             "winding_resistance_degC, winding_resistance_sd_K, magnet_flux_degC, "
             "magnet_flux_sd_K, voltage_reading, r0_error, psi0_error, voltage_offset_V, "
             "identifier_winding_degC, the daemon's CSV columns); "
             "'-' is standard output (the default)")
          ->capture_default_str();
      opt->motor_option = app.add_option("--motor", opt->motor,
                                         "motor description: a preset (han2019-tmp) or a TOML file")
                              ->capture_default_str();
      app.add_option("--model,-m", opt->model,
                     "with --log: run the daemon's fused estimator of this thermal model "
                     "(shipped name or path; the winding from the voltages) for one pump of the "
                     "recording instead of the paper's DFRLS, exactly as pumpthermd -r would");
      app.add_option("--config", opt->config,
                     "with --log: the daemon's configuration file; with --pump, its pump's "
                     "settings (model, motor, node ID) for the fused estimator");
      app.add_option("--pump", opt->pump, "with --config: the [[pump]] to run");
      opt->paper_only.push_back(
          app.add_option("--block", opt->block_samples,
                         "samples averaged per identification step (100 at 10 ms = 1 s)")
              ->check(CLI::Range(1, 1000000))
              ->capture_default_str());
      opt->paper_only.push_back(
          app.add_option("--min-current", opt->min_current_A,
                         "A: ignore blocks with a smaller mean |iq| (about 3x the inverter's "
                         "dead-time knee; 0 uses all)")
              ->check(CLI::Range(0.0, 1000.0))
              ->capture_default_str());
      app.footer(
          "status codes: 0 initialising, 1 converging, 2 tracking, 3 not_identifiable (Rs held),\n"
          "4 implausible (outside the motor's plausible band), 5 invalid_input (sample ignored),\n"
          "6 held (Rs not separable from a voltage offset, e.g. a run-up at constant current).\n"
          "Bad input (missing column, non-numeric cell, NaN, time not increasing): exit code 2.\n"
          "With --model or --config: the daemon's fused estimator on --log (one pump); a summary\n"
          "on stderr: how long the winding from resistance was published, its last value, R0 and\n"
          "psi0 against the nameplate.\n"
          "Examples:\n"
          "  pumptherm identify --input telemetry.csv --motor han2019-tmp --output rs.csv\n"
          "  pumptherm identify --model tmp-generic --log demo.log --node-id 3 -o fused3.csv\n"
          "  pumptherm identify --config /etc/pumptherm/pumpthermd.toml --pump pump3 --log "
          "bus.log");
      return [opt]() {
        if (!opt->model.empty() || !opt->config.empty() || !opt->pump.empty())
          return RunFused(*opt);
        return Run(opt->input, opt->recording, opt->output, opt->motor, opt->block_samples,
                   opt->min_current_A);
      };
    }};

}  // namespace
}  // namespace pumptherm::tools
