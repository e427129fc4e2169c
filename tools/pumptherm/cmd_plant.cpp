// pumptherm plant: the pump plant simulator (docs/plant-simulator.md). Reads a scenario (a bundled
// name or a path), resolves its model and motor files, runs tools/plant and writes the candump
// log, the truth and measured CSVs and summary.json into the output directory.
#include <fmt/core.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "tools/plant/plant.hpp"
#include "tools/pumptherm/model_files.hpp"
#include "tools/pumptherm/subcommand.hpp"

namespace pumptherm::tools {
namespace {

namespace fs = std::filesystem;

struct PlantOptions {
  std::string scenario;
  std::string out_dir = "plant-out";
  std::string dbc;
  std::string mapping;
  long long seed = -1;
  double duration_s = 0.0;
  bool list = false;
  bool quiet = false;
};

std::string ReadText(const fs::path& path) {
  try {
    return shipped::ReadTextFile(path);
  } catch (const std::runtime_error& e) {
    throw InputError(e.what());
  }
}

/// A scenario named by path, or a shipped one by name (shipped/shipped_files.hpp).
fs::path ResolveScenario(const std::string& arg) {
  try {
    return shipped::Resolve(shipped::FileKind::kScenario, arg);
  } catch (const shipped::FileNotFound& e) {
    throw InputError(e.what());
  }
}

/// Lists the scenarios of the first shipped scenario directory that exists.
void ListScenarios() {
  for (const fs::path d : shipped::SearchDirs(shipped::FileKind::kScenario)) {
    std::error_code ec;
    if (!fs::is_directory(d, ec)) continue;
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(d)) {
      if (e.path().extension() == ".toml") files.push_back(e.path());
    }
    std::sort(files.begin(), files.end());
    for (const fs::path& f : files) {
      try {
        const plant::Scenario sc = plant::ParseScenario(ReadText(f), f.string());
        fmt::print("{:<18} {:>3} pump(s) {:>7.0f} s  {}\n", f.stem().string(), sc.pumps.size(),
                   sc.duration_s, sc.description);
      } catch (const std::exception& e) {
        fmt::print("{:<18} (does not parse: {})\n", f.stem().string(), e.what());
      }
    }
    return;
  }
}

/// A progress bar on stderr, redrawn in place (only used when stderr is a terminal).
void DrawProgress(double fraction, const std::string& name) {
  constexpr int kWidth = 40;
  const int filled = static_cast<int>(fraction * kWidth);
  std::string bar(static_cast<std::size_t>(filled), '#');
  bar.resize(kWidth, '.');
  fmt::print(stderr, "\r{} [{}] {:3.0f} %", name, bar, 100.0 * fraction);
  if (fraction >= 1.0) fmt::print(stderr, "\n");
  std::fflush(stderr);
}

int RunPlantCommand(const PlantOptions& o) {
  if (o.list) {
    ListScenarios();
    return 0;
  }
  if (o.scenario.empty())
    throw InputError("give a scenario (a bundled name or a .toml path); --list shows them");
  const fs::path scenario_path = ResolveScenario(o.scenario);
  plant::Scenario sc;
  try {
    sc = plant::ParseScenario(ReadText(scenario_path), scenario_path.string());
  } catch (const plant::ScenarioError& e) {
    throw InputError(e.what());
  }
  if (o.seed >= 0) sc.seed = static_cast<std::uint64_t>(o.seed);
  if (o.duration_s > 0.0) sc.duration_s = o.duration_s;

  const fs::path base = scenario_path.parent_path();
  plant::PlantResources res;
  // Paths in a scenario are relative to the scenario file; names are shipped models.
  res.model = [&](const std::string& ref) {
    std::string arg = ref;
    if ((ref.find('/') != std::string::npos || ref.ends_with(".toml")) &&
        fs::path(ref).is_relative()) {
      arg = (base / ref).string();
    }
    const std::string path = ResolveModelPath(arg);
    return plant::LoadedText{ReadText(path), path};
  };
  res.read_file = [](const std::string& path) { return ReadText(path); };
  res.motor_file = [&](const std::string& ref) {
    const fs::path p = fs::path(ref).is_relative() ? base / ref : fs::path(ref);
    if (!fs::exists(p)) {
      throw InputError(fmt::format("motor '{}' is neither a preset nor an existing file", ref));
    }
    return plant::LoadedText{ReadText(p), p.string()};
  };
  if (sc.can_log) {
    // The shipped frame layout, found as the daemon finds it (shipped/shipped_files.hpp).
    auto shipped_dbc = [](const char* name) {
      try {
        return fs::path(shipped::Resolve(shipped::FileKind::kDbc, name));
      } catch (const shipped::FileNotFound& e) {
        throw InputError(e.what());
      }
    };
    const fs::path dbc = o.dbc.empty() ? shipped_dbc("pumptherm.dbc") : fs::path(o.dbc);
    const fs::path map =
        o.mapping.empty() ? shipped_dbc("mapping_pumptherm.toml") : fs::path(o.mapping);
    res.dbc = {ReadText(dbc), dbc.string()};
    res.mapping = {ReadText(map), map.string()};
  }
  const bool bar = !o.quiet && isatty(STDERR_FILENO) == 1;
  std::function<void(double)> progress;
  if (bar) progress = [&](double f) { DrawProgress(f, sc.name); };
  const auto start = std::chrono::steady_clock::now();
  plant::PlantResult r;
  try {
    r = plant::RunPlant(sc, res, o.out_dir, progress);
  } catch (const plant::ScenarioError& e) {
    throw InputError(e.what());
  }
  const double wall_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (!o.quiet) {
    fmt::print("scenario {} ({} pumps, {} s simulated, seed {}) in {:.1f} s\n", sc.name,
               sc.pumps.size(), sc.duration_s, sc.seed, wall_s);
    if (!r.log_path.empty())
      fmt::print("  candump log: {} ({} frames)\n", r.log_path, r.frames_written);
    for (const plant::PumpSummary& p : r.pumps) {
      auto when = [](double t) {
        return t < 0.0 ? std::string("never") : fmt::format("{:.0f} s", t);
      };
      const std::string where =
          sc.can_log ? fmt::format("{}:{}", p.interface, p.node_id) : std::string("-");
      fmt::print(
          "  {:<10} {:<7} max {} {:.1f} degC at {:.0f} s, warning ({} degC) {}, trip ({} degC) "
          "{}\n",
          p.name, where, sc.levels.node, p.max_level_node_degC, p.max_level_time_s,
          sc.levels.warning_degC, when(p.warning_crossed_s), sc.levels.trip_degC,
          when(p.trip_crossed_s));
    }
    fmt::print("  truth, measured CSVs and summary.json in {}\n", o.out_dir);
  }
  return 0;
}

const SubcommandRegistrar kPlantRegistrar{
    "plant",
    "Simulate pumps (drive, thermal truth, sensors, faults): candump log + truth/measured CSVs",
    [](CLI::App& app) -> std::function<int()> {
      auto o = std::make_shared<PlantOptions>();
      app.add_option("scenario", o->scenario,
                     "Bundled scenario name (demo, fleet32, saheba2010-fig4, ...) or a .toml path");
      app.add_option("--out,-o", o->out_dir, "Output directory (created if missing)")
          ->capture_default_str();
      app.add_option("--seed", o->seed, "Override the scenario's seed (same seed => same bytes)");
      app.add_option("--duration-s", o->duration_s, "Override the scenario's duration, s");
      app.add_option("--dbc", o->dbc, "Frame layout (default: the shipped protocol/pumptherm.dbc)");
      app.add_option("--mapping", o->mapping,
                     "Signal mapping (default: protocol/mapping_pumptherm.toml)");
      app.add_flag("--list", o->list, "List the bundled scenarios and exit");
      app.add_flag("--quiet,-q", o->quiet, "No progress bar and no summary");
      app.footer(
          "Example:\n"
          "  pumptherm plant demo --out demo-out\n"
          "  -> demo-out/demo.log (candump, replay with canplayer or pumpthermd -r),\n"
          "     demo-out/pump1.truth.csv, demo-out/pump1.measured.csv, ..., demo-out/summary.json\n"
          "Scenario format: docs/plant-simulator.md");
      return [o] { return RunPlantCommand(*o); };
    }};

}  // namespace
}  // namespace pumptherm::tools
