// pumptherm plot: per-node estimated against true temperatures and an alarm timeline, as PNG or
// SVG, drawn by gnuplot (run as a subprocess with a generated script). Inputs are the CSV files of
// `pumptherm plant` (truth, measured) and of the daemon or `pumptherm estimate` (estimates with
// optional alarm_level / alarm_reason columns). docs/plant-simulator.md, "pumptherm plot".
#include <fmt/core.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>
#include <system_error>

#include "tools/common/csv.hpp"
#include "tools/pumptherm/subcommand.hpp"

namespace pumptherm::tools {
namespace {

namespace fs = std::filesystem;

struct PlotOptions {
  std::vector<std::string> truth;
  std::vector<std::string> estimate;
  std::vector<std::string> events;
  std::vector<std::string> labels;
  std::vector<std::string> nodes;
  std::vector<std::string> extras;  ///< estimate columns drawn as points: COLUMN or COLUMN=NODE
  bool no_bands = false;            ///< no +-2 sd bands from the estimate's <node>_sd_K
  std::string out;
  std::string title;
  std::string gnuplot = "gnuplot";
  double warning_degC = std::nan("");
  double trip_degC = std::nan("");
  std::string level_node;
  std::string estimate_name = "estimate";
  int width_px = 1200;
  int row_height_px = 320;
  bool keep_script = false;
  double time_origin_s = std::nan("");  ///< Unix time drawn as t = 0 (NaN: from the files)
};

/// One pump's series.
struct Series {
  std::string label;
  std::optional<CsvTable> truth, estimate, events;
  double first_warning_s = std::nan(""), first_trip_s = std::nan("");  // from events
  double truth_warning_s = std::nan(""), truth_trip_s = std::nan("");  // from the truth
};

CsvTable ReadCsv(const std::string& path) {
  try {
    return CsvTable::Read(path);
  } catch (const CsvError& e) {
    throw InputError(e.what());
  }
}

std::vector<double> Col(const CsvTable& t, std::string_view name) {
  try {
    return t.ColumnAllowingNaN(name);
  } catch (const CsvError& e) {
    throw InputError(e.what());
  }
}

std::vector<double> RawTimes(const CsvTable& t) {
  try {
    return t.Time();
  } catch (const CsvError& e) {
    throw InputError(e.what());
  }
}

/// A time_s from this on is Unix time (2001-09-09): no run is 31 years long, so a file whose
/// first time is at or above it holds Unix time, and one below it time since its run's start.
constexpr double kUnixTimeFrom_s = 1e9;

/// The common time axis: Unix-time files are drawn less `origin_s`, relative ones as written.
struct TimeAxis {
  double origin_s = 0.0;
};

std::vector<double> Times(const CsvTable& t, const TimeAxis& axis) {
  std::vector<double> time = RawTimes(t);
  if (!time.empty() && time.front() >= kUnixTimeFrom_s) {
    for (double& x : time) x -= axis.origin_s;
  }
  return time;
}

/// The origin that puts Unix-time files on the relative files' axis: `given_s` if set (the
/// Unix time of the relative files' t = 0, e.g. the recording's first timestamp), else the
/// earliest Unix-time file's first time, down to the whole second. Says on stderr, per file,
/// how its time is drawn.
TimeAxis AlignTimes(const std::vector<const CsvTable*>& tables, double given_s) {
  TimeAxis axis;
  double earliest = std::numeric_limits<double>::infinity();
  for (const CsvTable* t : tables) {
    const std::vector<double> time = RawTimes(*t);
    if (!time.empty() && time.front() >= kUnixTimeFrom_s)
      earliest = std::min(earliest, time.front());
  }
  axis.origin_s = std::isfinite(given_s)    ? given_s
                  : std::isfinite(earliest) ? std::floor(earliest)
                                            : 0.0;
  for (const CsvTable* t : tables) {
    const std::vector<double> time = RawTimes(*t);
    if (time.empty() || time.front() < kUnixTimeFrom_s) {
      fmt::print(stderr, "plot: {}: time_s is time since its run's start, drawn as written\n",
                 t->source());
    } else {
      fmt::print(
          stderr,
          "plot: {}: time_s is Unix time, drawn as time since {:.3f} ({}); its first row at {:.3f} "
          "s\n",
          t->source(), axis.origin_s,
          std::isfinite(given_s)
              ? "--time-origin"
              : "the earliest Unix-time file's first whole second; --time-origin sets another",
          time.front() - axis.origin_s);
    }
  }
  return axis;
}

/// A gnuplot single-quoted string (no escapes inside; a quote is doubled). The terminals are
/// set `noenhanced`, so underscores in node names print as they are.
std::string Quote(std::string_view s) {
  std::string out = "'";
  for (char c : s) {
    if (c == '\'') out += '\'';
    out += c;
  }
  return out + "'";
}

/// Writes columns as a whitespace data file for gnuplot (NaN stays "NaN": a gap in the line).
void WriteData(const fs::path& path, const std::vector<std::vector<double>>& cols) {
  std::ofstream f(path);
  if (!f)
    throw std::system_error(errno, std::generic_category(),
                            fmt::format("writing '{}'", path.string()));
  const std::size_t rows = cols.empty() ? 0 : cols[0].size();
  for (std::size_t r = 0; r < rows; ++r) {
    for (std::size_t c = 0; c < cols.size(); ++c) {
      const double v = cols[c][r];
      f << (c ? " " : "") << (std::isfinite(v) ? fmt::format("{}", v) : std::string("NaN"));
    }
    f << '\n';
  }
  if (!f)
    throw std::system_error(errno, std::generic_category(),
                            fmt::format("writing '{}'", path.string()));
}

double FirstAtOrAbove(const std::vector<double>& t, const std::vector<double>& v, double level) {
  for (std::size_t i = 0; i < v.size(); ++i) {
    if (v[i] >= level) return t[i];
  }
  return std::nan("");
}

/// Appends to `lines` a translucent band estimate +- 2 sd (from `<node>_sd_K`) per node that
/// has one, in the node's colour, written to `file`.
void AddBands(const CsvTable& t, const TimeAxis& axis, const std::vector<std::string>& nodes,
              const fs::path& file, std::string& lines) {
  const std::vector<double> time = Times(t, axis);
  std::vector<std::vector<double>> cols{std::vector<double>(time.size())};
  for (std::size_t r = 0; r < time.size(); ++r) cols[0][r] = time[r] / 60.0;
  std::vector<std::size_t> colours;
  for (std::size_t k = 0; k < nodes.size(); ++k) {
    if (!t.Has(nodes[k] + "_C") || !t.Has(nodes[k] + "_sd_K")) continue;
    const auto v = Col(t, nodes[k] + "_C");
    const auto sd = Col(t, nodes[k] + "_sd_K");
    std::vector<double> lo(v.size()), hi(v.size());
    for (std::size_t r = 0; r < v.size(); ++r) {
      lo[r] = v[r] - 2.0 * sd[r];
      hi[r] = v[r] + 2.0 * sd[r];
    }
    cols.push_back(std::move(lo));
    cols.push_back(std::move(hi));
    colours.push_back(k + 1);
  }
  if (colours.empty()) return;
  WriteData(file, cols);
  for (std::size_t c = 0; c < colours.size(); ++c) {
    lines += fmt::format(
        "{}{} using 1:{}:{} with filledcurves lc {} fs transparent solid 0.18 noborder {}",
        lines.empty() ? "" : ", ", Quote(file.string()), 2 + 2 * c, 3 + 2 * c, colours[c],
        c == 0 ? "title '+-2 sd'" : "notitle");
  }
}

/// Appends to `lines` the extra estimate columns as small points (colour 0: black).
void AddExtras(const CsvTable& t, const TimeAxis& axis,
               const std::vector<std::pair<std::string, std::size_t>>& extras, const fs::path& file,
               std::string& lines) {
  if (extras.empty()) return;
  const std::vector<double> time = Times(t, axis);
  std::vector<std::vector<double>> cols{std::vector<double>(time.size())};
  for (std::size_t r = 0; r < time.size(); ++r) cols[0][r] = time[r] / 60.0;
  for (const auto& e : extras) cols.push_back(Col(t, e.first));
  WriteData(file, cols);
  for (std::size_t c = 0; c < extras.size(); ++c) {
    const std::string colour =
        extras[c].second == 0 ? "rgb 'black'" : fmt::format("{}", extras[c].second);
    lines += fmt::format("{}{} using 1:{} with points pt {} ps 0.35 lc {} title {}",
                         lines.empty() ? "" : ", ", Quote(file.string()), c + 2, c % 2 == 0 ? 7 : 5,
                         colour, Quote(extras[c].first));
  }
}

int RunPlot(const PlotOptions& o) {
  if (o.truth.empty() && o.estimate.empty())
    throw InputError("give --truth and/or --estimate CSV files");
  const std::size_t n = std::max(o.truth.size(), o.estimate.size());
  auto check_count = [&](const std::vector<std::string>& v, std::string_view what) {
    if (!v.empty() && v.size() != n) {
      throw InputError(fmt::format("{} {} file(s) for {} pump(s): give one per pump or none",
                                   v.size(), what, n));
    }
  };
  check_count(o.truth, "--truth");
  check_count(o.estimate, "--estimate");
  check_count(o.events, "--events");
  check_count(o.labels, "--label");
  if (o.out.empty()) throw InputError("give --out FILE.png or FILE.svg");
  const std::string ext = fs::path(o.out).extension().string();
  if (ext != ".png" && ext != ".svg")
    throw InputError(fmt::format("--out '{}': the name must end in .png or .svg", o.out));

  std::vector<Series> series(n);
  for (std::size_t i = 0; i < n; ++i) {
    Series& s = series[i];
    if (!o.truth.empty()) s.truth = ReadCsv(o.truth[i]);
    if (!o.estimate.empty()) s.estimate = ReadCsv(o.estimate[i]);
    if (!o.events.empty()) {
      s.events = ReadCsv(o.events[i]);
    } else if (s.estimate && s.estimate->Has("alarm_level")) {
      s.events = s.estimate;
    }
    s.label = !o.labels.empty()  ? o.labels[i]
              : !o.truth.empty() ? fs::path(o.truth[i]).stem().stem().string()
                                 : fs::path(o.estimate[i]).stem().string();
  }

  std::vector<const CsvTable*> tables;
  for (const Series& s : series) {
    for (const auto* t : {&s.truth, &s.estimate, &s.events}) {
      // The events default to a copy of the estimate: one line per file.
      const bool seen = *t && std::any_of(tables.begin(), tables.end(), [&](const CsvTable* x) {
        return x->source() == (*t)->source();
      });
      if (*t && !seen) tables.push_back(&**t);
    }
  }
  const TimeAxis axis = AlignTimes(tables, o.time_origin_s);

  // Nodes: given, or every <node>_C column the truth and the estimate share (else the truth's).
  std::vector<std::string> nodes = o.nodes;
  if (nodes.empty()) {
    const CsvTable& ref = series[0].truth ? *series[0].truth : *series[0].estimate;
    for (const std::string& c : ref.columns()) {
      if (!c.ends_with("_C") || c == "ambient_C" || c == "time_s") continue;
      const std::string node = c.substr(0, c.size() - 2);
      if (series[0].truth && series[0].estimate && !series[0].estimate->Has(c)) continue;
      nodes.push_back(node);
    }
    if (nodes.empty())
      throw InputError(fmt::format("{}: no <node>_C columns to plot; give --nodes", ref.source()));
  }
  for (const Series& s : series) {
    for (const std::string& node : nodes) {
      const bool in_truth = s.truth && s.truth->Has(node + "_C");
      const bool in_est = s.estimate && s.estimate->Has(node + "_C");
      if (!in_truth && !in_est) {
        throw InputError(fmt::format("column '{}_C' is in neither {} nor {}", node,
                                     s.truth ? s.truth->source() : "(no truth)",
                                     s.estimate ? s.estimate->source() : "(no estimate)"));
      }
    }
  }

  const fs::path dir = fs::temp_directory_path() / fmt::format("pumptherm-plot-{}", getpid());
  fs::create_directories(dir);
  struct Cleanup {
    fs::path d;
    bool keep;
    ~Cleanup() {
      std::error_code ec;
      if (!keep) fs::remove_all(d, ec);
    }
  } cleanup{dir, o.keep_script};

  // Extra estimate columns: (column, colour index: 1 + the node's position, else 0 = black).
  std::vector<std::pair<std::string, std::size_t>> extras;
  for (const std::string& e : o.extras) {
    const std::size_t eq = e.find('=');
    const std::string column = e.substr(0, eq);
    const std::string node = eq == std::string::npos ? "" : e.substr(eq + 1);
    const auto it = std::find(nodes.begin(), nodes.end(), node);
    extras.emplace_back(column,
                        it == nodes.end() ? 0 : 1 + static_cast<std::size_t>(it - nodes.begin()));
    for (const Series& s : series) {
      if (s.estimate && !s.estimate->Has(column)) {
        throw InputError(
            fmt::format("--extra: column '{}' is not in {}", column, s.estimate->source()));
      }
    }
  }

  const std::string level_node = !o.level_node.empty() ? o.level_node : nodes[0];
  std::string plots;
  bool any_events = false;
  double t_max_min = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    Series& s = series[i];
    std::string lines;
    auto add_table = [&](const CsvTable& t, const std::string& tag, const char* dash) {
      const std::vector<double> time = Times(t, axis);
      std::vector<std::vector<double>> cols{std::vector<double>(time.size())};
      for (std::size_t r = 0; r < time.size(); ++r) cols[0][r] = time[r] / 60.0;
      if (!time.empty()) t_max_min = std::max(t_max_min, time.back() / 60.0);
      std::vector<std::string> names;
      for (const std::string& node : nodes) {
        if (!t.Has(node + "_C")) continue;
        cols.push_back(Col(t, node + "_C"));
        names.push_back(node);
      }
      const fs::path file = dir / fmt::format("p{}_{}.dat", i, tag);
      WriteData(file, cols);
      for (std::size_t c = 0; c < names.size(); ++c) {
        const std::size_t colour =
            1 + std::find(nodes.begin(), nodes.end(), names[c]) - nodes.begin();
        lines += fmt::format("{}{} using 1:{} with lines lc {} dt {} lw 2 title {}",
                             lines.empty() ? "" : ", ", Quote(file.string()), c + 2, colour, dash,
                             Quote(names[c] + " " + tag));
      }
    };
    if (s.truth) {
      add_table(*s.truth, "truth", "1");
      if (std::isfinite(o.warning_degC) && s.truth->Has(level_node + "_C")) {
        const auto t = Times(*s.truth, axis);
        const auto v = Col(*s.truth, level_node + "_C");
        s.truth_warning_s = FirstAtOrAbove(t, v, o.warning_degC);
        if (std::isfinite(o.trip_degC)) s.truth_trip_s = FirstAtOrAbove(t, v, o.trip_degC);
      }
    }
    if (s.estimate) {
      if (!o.no_bands)
        AddBands(*s.estimate, axis, nodes, dir / fmt::format("p{}_band.dat", i), lines);
      add_table(*s.estimate, o.estimate_name, "2");
      AddExtras(*s.estimate, axis, extras, dir / fmt::format("p{}_extra.dat", i), lines);
    }
    std::string marks;
    if (s.events) {
      any_events = true;
      const auto t = Times(*s.events, axis);
      const auto level = Col(*s.events, "alarm_level");
      s.first_warning_s = FirstAtOrAbove(t, level, 1.0);
      s.first_trip_s = FirstAtOrAbove(t, level, 2.0);
    }
    // Alarm moments: solid lines, labels right of them at the top; true crossings: dotted
    // lines, labels left of them lower down, so the two never overlap.
    auto vline = [&](double t_s, const char* colour, const char* dash, const std::string& text,
                     bool alarm) {
      if (!std::isfinite(t_s)) return;
      marks += fmt::format(
          "set arrow from {0},graph 0 to {0},graph 1 nohead lc rgb '{1}' dt {2} lw 2 front\n"
          "set label {3} at {0},graph {4} {5} tc rgb '{1}' front\n",
          t_s / 60.0, colour, dash, Quote(text), alarm ? 0.95 : 0.85,
          alarm ? "left offset 0.5,0" : "right offset -0.5,0");
    };
    vline(s.first_warning_s, "#e69f00", "1", fmt::format("warning {:.0f} s", s.first_warning_s),
          true);
    vline(s.first_trip_s, "#d00000", "1", fmt::format("trip {:.0f} s", s.first_trip_s), true);
    vline(s.truth_warning_s, "#e69f00", "3",
          fmt::format("true > warning {:.0f} s", s.truth_warning_s), false);
    vline(s.truth_trip_s, "#d00000", "3", fmt::format("true > trip {:.0f} s", s.truth_trip_s),
          false);
    std::string levels;
    if (std::isfinite(o.warning_degC))
      levels += fmt::format(", {} with lines lc rgb '#e69f00' dt 4 title 'warning level'",
                            o.warning_degC);
    if (std::isfinite(o.trip_degC))
      levels +=
          fmt::format(", {} with lines lc rgb '#d00000' dt 4 title 'trip level'", o.trip_degC);
    plots += fmt::format(
        "unset arrow\nunset label\n{}set title {}\nset ylabel 'temperature (degC)'\nplot {}{}\n",
        marks, Quote(s.label), lines, levels);
  }
  if (any_events) {
    std::string lines;
    for (std::size_t i = 0; i < n; ++i) {
      if (!series[i].events) continue;
      const auto t = Times(*series[i].events, axis);
      std::vector<std::vector<double>> cols{std::vector<double>(t.size()),
                                            Col(*series[i].events, "alarm_level")};
      for (std::size_t r = 0; r < t.size(); ++r) cols[0][r] = t[r] / 60.0;
      for (double& v : cols[1]) v += 0.04 * static_cast<double>(i);  // keep overlapping steps apart
      if (!t.empty() && cols[0].back() < t_max_min) {  // hold the last level to the plot's end
        cols[0].push_back(t_max_min);
        cols[1].push_back(cols[1].back());
      }
      const fs::path file = dir / fmt::format("p{}_alarm.dat", i);
      WriteData(file, cols);
      lines +=
          fmt::format("{}{} using 1:2 with steps lw 2 lc {} title {}", lines.empty() ? "" : ", ",
                      Quote(file.string()), i + 1, Quote(series[i].label));
    }
    plots +=
        "unset arrow\nunset label\nset title 'alarm level'\nset ylabel 'level'\n"
        "set yrange [-0.2:2.5]\nset ytics ('normal' 0, 'warning' 1, 'trip' 2)\n"
        "plot " +
        lines + "\n";
  }

  const int rows = static_cast<int>(n) + (any_events ? 1 : 0);
  const int height = o.row_height_px * rows + 60;
  std::string script;
  if (ext == ".png") {
    script += fmt::format("set terminal pngcairo size {},{} font 'sans,10' noenhanced\n",
                          o.width_px, height);
  } else {
    script += fmt::format("set terminal svg size {},{} dynamic font 'sans,10' noenhanced\n",
                          o.width_px, height);
  }
  script += fmt::format("set output {}\n", Quote(fs::absolute(o.out).string()));
  script += fmt::format("set multiplot layout {},1 title {}\n", rows, Quote(o.title));
  // Fixed margins so the panels' time axes line up whatever the tick labels and keys.
  script += fmt::format(
      "set grid\nset key outside right top\nset xlabel 'time (min)'\nset xrange [0:{}]\n"
      "set lmargin at screen 0.08\nset rmargin at screen 0.80\n",
      t_max_min);
  script += plots;
  script += "unset multiplot\n";
  const fs::path script_path = dir / "plot.gp";
  {
    std::ofstream f(script_path);
    f << script;
    if (!f) throw std::system_error(errno, std::generic_category(), "writing the gnuplot script");
  }
  // The script path is ours (temp dir + pid); the executable name is the user's own option.
  const std::string cmd = fmt::format("{} '{}' 2>&1", o.gnuplot, script_path.string());
  std::FILE* pipe = popen(cmd.c_str(), "r");
  if (pipe == nullptr) throw std::system_error(errno, std::generic_category(), "starting gnuplot");
  std::string output;
  char buf[512];
  while (std::fgets(buf, sizeof buf, pipe) != nullptr) output += buf;
  const int status = pclose(pipe);
  if (status == -1 || !WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    if (WIFEXITED(status) && WEXITSTATUS(status) == 127) {
      throw std::runtime_error(
          fmt::format("gnuplot ('{}') is not installed or not on PATH; install the "
                      "Debian package gnuplot-nox (tools/setup.sh does)",
                      o.gnuplot));
    }
    throw std::runtime_error(
        fmt::format("gnuplot failed (script {}{}):\n{}", script_path.string(),
                    o.keep_script ? "" : ", rerun with --keep-script to keep it", output));
  }
  if (o.keep_script) fmt::print(stderr, "gnuplot script and data kept in {}\n", dir.string());
  fmt::print("wrote {}\n", o.out);
  for (const Series& s : series) {
    auto when = [](double t) {
      return std::isfinite(t) ? fmt::format("{:.0f} s", t) : std::string("-");
    };
    if (s.events || std::isfinite(o.warning_degC)) {
      fmt::print(
          "  {:<12} alarm warning {:>7}  trip {:>7}   truth {} crosses warning {:>7}  trip {:>7}\n",
          s.label, when(s.first_warning_s), when(s.first_trip_s), level_node,
          when(s.truth_warning_s), when(s.truth_trip_s));
    }
  }
  return 0;
}

const SubcommandRegistrar kRegistrar{
    "plot", "Plot estimated against true temperatures and the alarm timeline (PNG/SVG via gnuplot)",
    [](CLI::App& app) -> std::function<int()> {
      auto o = std::make_shared<PlotOptions>();
      app.add_option("--truth,-t", o->truth,
                     "Truth CSV per pump (time_s, <node>_C), e.g. from `pumptherm plant`");
      app.add_option(
          "--estimate,-e", o->estimate,
          "Estimate CSV per pump (time_s, <node>_C; alarm_level, alarm_reason if present)");
      app.add_option(
          "--events", o->events,
          "CSV per pump with time_s and alarm_level (0 normal, 1 warning, 2 trip); default: the "
          "estimate CSV when it has alarm_level");
      app.add_option("--label", o->labels, "Panel title per pump (default: the file name)");
      app.add_option("--nodes,-n", o->nodes,
                     "Nodes to plot (default: every <node>_C column both files have)")
          ->delimiter(',');
      app.add_option(
             "--extra", o->extras,
             "Estimate columns drawn as points, COLUMN or COLUMN=NODE (in that node's colour), "
             "e.g. winding_resistance_C=winding,magnet_flux_C=rotor")
          ->delimiter(',');
      app.add_flag("--no-bands", o->no_bands,
                   "Do not draw the +-2 sd bands of the estimate's <node>_sd_K");
      app.add_option("--warning-C", o->warning_degC,
                     "Warning level, degC: drawn, and its true crossing marked");
      app.add_option("--trip-C", o->trip_degC,
                     "Trip level, degC: drawn, and its true crossing marked");
      app.add_option(
          "--level-node", o->level_node,
          "Node whose truth is checked against the levels (default: the first of --nodes)");
      app.add_option("--title", o->title, "Title of the figure");
      app.add_option(
             "--estimate-name", o->estimate_name,
             "What the --estimate series are called in the legend (e.g. RTD for a measured CSV)")
          ->capture_default_str();
      app.add_option("--out,-o", o->out, "Output file, .png or .svg")->required();
      app.add_option("--width", o->width_px, "Width in pixels")->capture_default_str();
      app.add_option("--row-height", o->row_height_px, "Height of one panel in pixels")
          ->capture_default_str();
      app.add_option("--gnuplot", o->gnuplot, "gnuplot executable")->capture_default_str();
      app.add_flag("--keep-script", o->keep_script,
                   "Keep the generated gnuplot script and data files");
      app.add_option(
          "--time-origin", o->time_origin_s,
          "Unix time (s) drawn as t = 0 for files whose time_s is Unix time (the daemon's CSV "
          "without --csv-time-origin), e.g. the recording's first timestamp; default: the "
          "earliest such file's first whole second");
      app.footer(
          "Example:\n"
          "  pumptherm plot --truth out/pump3.truth.csv --estimate est3.csv --nodes winding,frame "
          "\\\n"
          "      --warning-C 100 --trip-C 120 --out pump3.png\n"
          "One panel per pump (repeat --truth/--estimate/--label in the same order), then the "
          "alarm\n"
          "timeline when alarm levels are given. Solid: truth; dashed: estimate; vertical lines: "
          "alarm\n"
          "moments (solid) and true level crossings (dotted); shaded: estimate +-2 sd where the\n"
          "estimate has <node>_sd_K; points: --extra columns.\n"
          "Time: a file whose time_s is Unix time (pumpthermd --csv-dir) is put on the axis of "
          "the\n"
          "relative files (plant, estimate) by --time-origin; standard error says, per file, how.");
      return [o] { return RunPlot(*o); };
    }};

}  // namespace
}  // namespace pumptherm::tools
