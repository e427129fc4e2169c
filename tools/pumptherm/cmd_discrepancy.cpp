// pumptherm discrepancy: find where a thermal model's simulation disagrees with measured data,
// name the missing effect, add it, show the gap shrink on data it did not fit
// (docs/discrepancy.md).
#include <fmt/core.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <sstream>

#include "estimators/model_effects.hpp"
#include "tools/common/csv.hpp"
#include "tools/discrepancy/report.hpp"
#include "tools/discrepancy/workflow.hpp"
#include "tools/pumptherm/model_files.hpp"
#include "tools/pumptherm/subcommand.hpp"

namespace pumptherm::tools {
namespace {

struct DiscrepancyOptions {
  std::string model, train, validate, out;
  std::vector<std::string> effects;
  int max_effects = 3;
  bool quiet = false;
};

int RunDiscrepancy(const DiscrepancyOptions& o) {
  const std::string path = ResolveModelPath(o.model);
  std::ifstream f(path);
  if (!f) throw InputError(fmt::format("cannot read model file '{}'", path));
  std::stringstream ss;
  ss << f.rdbuf();
  const std::string text = ss.str();
  const estimators::ThermalModel model = LoadThermalModel(path);
  for (const std::string& e : o.effects)
    if (estimators::FindEffect(e) == nullptr) {
      std::string names;
      for (const auto& spec : estimators::EffectVocabulary()) names += " " + spec.name;
      throw InputError(fmt::format("--effects: unknown effect '{}' (known:{})", e, names));
    }
  if (o.max_effects < 1) throw InputError("--max-effects must be at least 1");
  discrepancy::Data train, validate;
  try {
    train = discrepancy::ReadData(o.train, model);
    validate = discrepancy::ReadData(o.validate, model);
  } catch (const CsvError& e) {
    throw InputError(e.what());
  }
  discrepancy::Options opt;
  opt.effects = o.effects;
  opt.max_effects = o.max_effects;
  if (!o.quiet && isatty(STDERR_FILENO) == 1)
    opt.progress = [](const std::string& line) { fmt::print(stderr, "\r\033[K{}\n", line); };
  discrepancy::Result r;
  try {
    r = discrepancy::Run(
        text, path, train, validate, opt,
        estimators::ThermalModelFiles{shipped::DirectoryOf(path), &shipped::ReadTextFile});
  } catch (const estimators::ThermalModelError& e) {
    throw InputError(e.what());
  } catch (const std::invalid_argument& e) {
    throw InputError(e.what());
  }
  discrepancy::ReportContext context;
  context.input_model_toml = discrepancy::ShortestFloats(
      estimators::ApplyModelEffects(text, path, {}, shipped::DirectoryOf(path)));
  context.options = opt;
  context.validate = &validate;
  discrepancy::WriteReport(o.out, r, o.model, o.train, o.validate, context);
  if (!o.quiet) {
    const auto& vb = r.validate_before.back();
    const auto& va = r.validate_after.back();
    std::string named;
    for (const auto& e : r.effects)
      named += (named.empty() ? "" : ", ") + e.effect.name +
               (e.effect.node.empty() ? "" : "(" + e.effect.node + ")");
    fmt::print(stderr,
               "{}\nverdict: {}{}\nvalidation gap: RMSE {:.3f} -> {:.3f} K, max {:.3f} -> {:.3f} "
               "K\nwrote {}/report.json, model.toml, report.html ({:.1f} s)\n",
               discrepancy::CheckModelRightNow(r, context).line, r.verdict,
               named.empty() ? "" : " (" + named + ")", vb.rmse_K, va.rmse_K, vb.max_abs_K,
               va.max_abs_K, o.out, r.seconds);
  }
  return 0;
}

const SubcommandRegistrar kDiscrepancyRegistrar{
    "discrepancy", "Name the effect a thermal model misses, add it, show the gap shrink",
    [](CLI::App& app) -> std::function<int()> {
      auto o = std::make_shared<DiscrepancyOptions>();
      app.add_option("--model,-m", o->model, "Shipped model name or path to a model .toml")
          ->required();
      app.add_option(
             "--train", o->train,
             "CSV to fit on: time_s, speed_rpm, id_A+iq_A or phase_current_rms_A, ambient_degC "
             "(coolant_degC), <node>_degC per measured node")
          ->required();
      app.add_option("--validate", o->validate, "CSV to score on (same columns, other data)")
          ->required();
      app.add_option("--out", o->out, "Directory for report.json, model.toml, report.html")
          ->required();
      app.add_option("--effects", o->effects, "Candidate effects (default: all)")->delimiter(',');
      app.add_option("--max-effects", o->max_effects, "Effects to add at most (default 3)");
      app.add_flag("--quiet,-q", o->quiet, "No progress and no summary");
      app.footer(
          "Effects: frame_thermal_mass, frame_ambient_resistance, speed_dependent_cooling,\n"
          "winding_conductance, copper_temperature_coefficient, iron_loss_scale, rotor_loss,\n"
          "sensor_lag, sensor_offset (docs/discrepancy.md).\n"
          "Example:\n  pumptherm discrepancy --model saheba2010-baseline --train train.csv "
          "--validate valid.csv --out disc/");
      return [o] { return RunDiscrepancy(*o); };
    }};

}  // namespace
}  // namespace pumptherm::tools
