// `pumptherm identify`: stator resistance, flux and winding temperature from dq telemetry
// (estimators/resistance_identifier.hpp; docs/resistance-identification.md).
#include <fmt/core.h>
#include <fmt/format.h>

#include <CLI/CLI.hpp>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "estimators/motor.hpp"
#include "estimators/resistance_identifier.hpp"
#include "tools/common/csv.hpp"
#include "tools/pumptherm/model_files.hpp"
#include "tools/pumptherm/recording.hpp"
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

const SubcommandRegistrar kRegistrar{
    "identify", "stator resistance, flux and winding temperature from dq telemetry",
    [](CLI::App& app) {
      struct Options {
        std::string input, output = "-", motor = "han2019-tmp";
        RecordingSource recording;
        int block_samples = 100;
        double min_current_A = 0.0;
      };
      auto opt = std::make_shared<Options>();
      app.add_option("--input,-i", opt->input,
                     "CSV with columns time_s, id_A, iq_A, ud_V, uq_V, speed_rpm (mechanical "
                     "r/min), any order; '-' reads standard input (or --log)");
      AddRecordingOptions(app, opt->recording);
      app.add_option(
             "--output,-o", opt->output,
             "CSV written with time_s, resistance_ohm, flux_Wb, winding_resistance_degC, status, "
             "winding_resistance_sd_K, flux_sd_Wb; "
             "'-' is standard output (the default)")
          ->capture_default_str();
      app.add_option("--motor", opt->motor,
                     "motor description: a preset (han2019-tmp) or a TOML file")
          ->capture_default_str();
      app.add_option("--block", opt->block_samples,
                     "samples averaged per identification step (100 at 10 ms = 1 s)")
          ->check(CLI::Range(1, 1000000))
          ->capture_default_str();
      app.add_option("--min-current", opt->min_current_A,
                     "A: ignore blocks with a smaller mean |iq| (about 3x the inverter's "
                     "dead-time knee; 0 uses all)")
          ->check(CLI::Range(0.0, 1000.0))
          ->capture_default_str();
      app.footer(
          "status codes: 0 initialising, 1 converging, 2 tracking, 3 not_identifiable (Rs held),\n"
          "4 implausible (outside the motor's plausible band), 5 invalid_input (sample ignored).\n"
          "Bad input (missing column, non-numeric cell, NaN, time not increasing): exit code 2.\n"
          "Example:\n"
          "  pumptherm identify --input telemetry.csv --motor han2019-tmp --output rs.csv");
      return [opt]() {
        return Run(opt->input, opt->recording, opt->output, opt->motor, opt->block_samples,
                   opt->min_current_A);
      };
    }};

}  // namespace
}  // namespace pumptherm::tools
