// pumptherm plot: per pump the estimated against the true temperatures, the estimate's error
// (estimate minus truth, with its +-2 sd band), the fault's onset and the daemon's diagnosis, and
// an alarm timeline, as PNG or SVG drawn by gnuplot (run as a subprocess with a generated script).
// Inputs are the CSV files of `pumptherm plant` (truth, measured) and of the daemon or `pumptherm
// estimate` (estimates with optional alarm and diagnosis columns). docs/plant-simulator.md,
// "pumptherm plot".
#include <fmt/core.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
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

#include "daemon/operator_text.hpp"
#include "estimators/mismatch_detector.hpp"
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
  std::vector<std::string> marks;   ///< T=TEXT: a moment (s) marked on every pump's panels
  bool no_bands = false;            ///< no +-2 sd bands from the estimate's <node>_sd_K
  bool no_errors = false;           ///< no error panels
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

/// A moment marked by a vertical line: when (s on the plot's axis), what, and how drawn.
struct Mark {
  double t_s = std::nan("");
  std::string text;
  std::string colour;
  int dash = 1;
};

/// One pump's series.
struct Series {
  std::string label;
  std::optional<CsvTable> truth, estimate, events;
  double first_warning_s = std::nan(""), first_trip_s = std::nan("");  // from events
  double truth_warning_s = std::nan(""), truth_trip_s = std::nan("");  // from the truth
  std::vector<Mark> marks;  ///< fault onsets, the diagnosis, the --mark moments
};

// Colours: one per node, none of them the warning's orange or the trip's red.
constexpr std::array<const char*, 8> kNodeColours{"#1f77b4", "#2ca02c", "#9467bd", "#8c564b",
                                                  "#17becf", "#7f7f7f", "#bcbd22", "#e377c2"};
constexpr const char* kWarningColour = "#e69f00";
constexpr const char* kTripColour = "#d00000";
constexpr const char* kFaultColour = "#000000";
constexpr const char* kDiagnosisColour = "#555555";

std::string NodeColour(std::size_t k) { return kNodeColours[k % kNodeColours.size()]; }

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

std::vector<double> Codes(const CsvTable& t, std::string_view name,
                          std::span<const std::string_view> words) {
  try {
    return t.Codes(name, words);
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

std::vector<double> Minutes(const std::vector<double>& t_s) {
  std::vector<double> m(t_s.size());
  for (std::size_t r = 0; r < t_s.size(); ++r) m[r] = t_s[r] / 60.0;
  return m;
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

bool AnyFinite(const std::vector<double>& v) {
  return std::any_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
}

/// `v` (sampled at `t`, increasing) at the times `at`, linear between samples; NaN outside.
std::vector<double> Interpolate(const std::vector<double>& t, const std::vector<double>& v,
                                const std::vector<double>& at) {
  std::vector<double> out(at.size(), std::nan(""));
  std::size_t j = 0;
  for (std::size_t i = 0; i < at.size(); ++i) {
    while (j + 1 < t.size() && t[j + 1] < at[i]) ++j;
    if (j + 1 >= t.size() || at[i] < t[j]) continue;
    const double w = (at[i] - t[j]) / (t[j + 1] - t[j]);
    out[i] = v[j] + w * (v[j + 1] - v[j]);
  }
  return out;
}

/// What a column is, as a person reads it: a node's name, "winding from resistance" for
/// `winding_resistance_degC`, "magnet from flux" for `magnet_flux_degC`, spaces for underscores.
std::string ReadableName(std::string column) {
  for (const char* suffix : {"_degC", "_C"}) {
    const std::string s(suffix);
    if (column.size() > s.size() && column.ends_with(s)) {
      column.resize(column.size() - s.size());
      break;
    }
  }
  if (column == "winding_resistance") return "winding from resistance";
  if (column == "magnet_flux") return "magnet from flux";
  if (column == "frame_sensor" || column == "frame_measured") return "frame sensor";
  std::replace(column.begin(), column.end(), '_', ' ');
  return column;
}

/// "13.8 min" on the plot's axis.
std::string MinutesText(double t_s) { return fmt::format("{:.1f} min", t_s / 60.0); }

// Codes as the CSV files write them, words or numbers (docs/daemon.md, "Names").
constexpr std::array<std::string_view, 3> kLevelWords{"normal", "warning", "trip"};
constexpr std::array<std::string_view, 5> kMismatchStateWords{
    "consistent", "learning", "plant_change", "sensor_fault_suspected", "unexplained"};

/// The cooling failures of the truth: every change of `cooling_model` (0 = the model as written).
void AddFaultMarks(const CsvTable& truth, const TimeAxis& axis, std::vector<Mark>& marks) {
  if (!truth.Has("cooling_model")) return;
  const auto t = Times(truth, axis);
  const auto m = Col(truth, "cooling_model");
  for (std::size_t r = 1; r < m.size(); ++r) {
    if (!(m[r] != m[r - 1]) || !std::isfinite(m[r])) continue;
    marks.push_back({t[r], m[r] > 0 ? "cooling fails" : "cooling restored", kFaultColour, 4});
  }
}

/// The daemon's diagnosis: the first moment its mismatch test blames the plant or the sensor,
/// and the first moment it names the effect ("diagnosis: cooling lost").
void AddDiagnosisMarks(const CsvTable& est, const TimeAxis& axis, std::vector<Mark>& marks) {
  if (!est.Has("mismatch_state")) return;
  std::vector<std::string_view> effect_words;
  for (int e = 0; e < estimators::kMismatchEffectCount; ++e)
    effect_words.push_back(
        estimators::MismatchEffectName(static_cast<estimators::MismatchEffect>(e)));
  const auto t = Times(est, axis);
  const auto state = Codes(est, "mismatch_state", kMismatchStateWords);
  const auto effect =
      est.Has("mismatch_effect") ? Codes(est, "mismatch_effect", effect_words) : state;
  const auto value = est.Has("mismatch_value") ? Col(est, "mismatch_value") : state;
  bool found = false;
  for (std::size_t r = 0; r < state.size(); ++r) {
    const auto s = static_cast<estimators::MismatchState>(std::isfinite(state[r]) ? state[r] : 1);
    if (!daemon::DiagnosisBlames(s)) continue;
    const bool named = est.Has("mismatch_effect") && effect[r] >= 1 &&
                       effect[r] < estimators::kMismatchEffectCount;
    if (!found && !named) marks.push_back({t[r], "model mismatch found", kDiagnosisColour, 2});
    found = true;
    if (named) {
      std::string cause = daemon::CauseText(s, static_cast<estimators::MismatchEffect>(effect[r]),
                                            value[r], "frame");
      marks.push_back({t[r], "diagnosis: " + cause, kDiagnosisColour, 2});
      return;
    }
  }
}

/// The `--mark T=TEXT` moments.
std::vector<Mark> UserMarks(const std::vector<std::string>& specs) {
  std::vector<Mark> out;
  for (const std::string& m : specs) {
    const std::size_t eq = m.find('=');
    char* end = nullptr;
    const std::string number = m.substr(0, eq);
    const double t = std::strtod(number.c_str(), &end);
    if (eq == std::string::npos || number.empty() || *end != '\0' || !std::isfinite(t))
      throw InputError(
          fmt::format("--mark '{}': expected SECONDS=TEXT, e.g. 240=cooling fails", m));
    out.push_back({t, m.substr(eq + 1), kFaultColour, 4});
  }
  return out;
}

/// Everything one figure draws, gathered before the script is written.
struct Figure {
  std::vector<std::string> nodes;
  std::vector<std::pair<std::string, std::size_t>> extras;  ///< column, colour index
  std::vector<bool> extra_drawn;  ///< an extra with a finite value in some pump's estimate
  bool any_truth = false, any_estimate = false, any_band = false, any_events = false;
  bool any_fault = false, any_diagnosis = false, any_error = false;
  double t_max_min = 0.0;
  fs::path dir;
};

/// The plot lines of one pump's temperature panel, with its data file written.
std::string TemperatureLines(const Series& s, std::size_t i, const TimeAxis& axis,
                             const PlotOptions& o, Figure& fig) {
  std::string lines;
  auto add = [&](const std::string& l) { lines += (lines.empty() ? "" : ", ") + l; };
  auto add_table = [&](const CsvTable& t, const std::string& tag, int dash) {
    const std::vector<double> time = Times(t, axis);
    std::vector<std::vector<double>> cols{Minutes(time)};
    if (!time.empty()) fig.t_max_min = std::max(fig.t_max_min, time.back() / 60.0);
    std::vector<std::size_t> colours;
    for (std::size_t k = 0; k < fig.nodes.size(); ++k) {
      if (!t.Has(fig.nodes[k] + "_degC")) continue;
      cols.push_back(Col(t, fig.nodes[k] + "_degC"));
      colours.push_back(k);
    }
    const fs::path file = fig.dir / fmt::format("p{}_{}.dat", i, tag);
    WriteData(file, cols);
    for (std::size_t c = 0; c < colours.size(); ++c)
      add(fmt::format("{} using 1:{} with lines lc rgb '{}' dt {} lw {} notitle",
                      Quote(file.string()), c + 2, NodeColour(colours[c]), dash,
                      dash == 1 ? 2.5 : 1.5));
  };
  if (s.estimate && !o.no_bands) {
    const CsvTable& t = *s.estimate;
    std::vector<std::vector<double>> cols{Minutes(Times(t, axis))};
    std::vector<std::size_t> colours;
    for (std::size_t k = 0; k < fig.nodes.size(); ++k) {
      const std::string& n = fig.nodes[k];
      if (!t.Has(n + "_degC") || !t.Has(n + "_sd_K")) continue;
      const auto v = Col(t, n + "_degC");
      const auto sd = Col(t, n + "_sd_K");
      std::vector<double> lo(v.size()), hi(v.size());
      for (std::size_t r = 0; r < v.size(); ++r) {
        lo[r] = v[r] - 2.0 * sd[r];
        hi[r] = v[r] + 2.0 * sd[r];
      }
      cols.push_back(std::move(lo));
      cols.push_back(std::move(hi));
      colours.push_back(k);
    }
    if (!colours.empty()) {
      const fs::path file = fig.dir / fmt::format("p{}_band.dat", i);
      WriteData(file, cols);
      fig.any_band = true;
      for (std::size_t c = 0; c < colours.size(); ++c)
        add(fmt::format(
            "{} using 1:{}:{} with filledcurves lc rgb '{}' fs transparent solid 0.15 noborder "
            "notitle",
            Quote(file.string()), 2 + 2 * c, 3 + 2 * c, NodeColour(colours[c])));
    }
  }
  if (s.truth) add_table(*s.truth, "truth", 1);
  if (s.estimate) add_table(*s.estimate, "estimate", 2);
  if (s.estimate && !fig.extras.empty()) {
    const CsvTable& t = *s.estimate;
    std::vector<std::vector<double>> cols{Minutes(Times(t, axis))};
    for (const auto& e : fig.extras) cols.push_back(Col(t, e.first));
    const fs::path file = fig.dir / fmt::format("p{}_extra.dat", i);
    WriteData(file, cols);
    for (std::size_t c = 0; c < fig.extras.size(); ++c) {
      if (!AnyFinite(cols[c + 1])) continue;
      add(fmt::format("{} using 1:{} with points pt {} ps 0.4 lc rgb '{}' notitle",
                      Quote(file.string()), c + 2, c % 2 == 0 ? 7 : 5,
                      fig.extras[c].second == 0 ? "black" : NodeColour(fig.extras[c].second - 1)));
    }
  }
  if (std::isfinite(o.warning_degC))
    add(fmt::format("{} with lines lc rgb '{}' dt 4 notitle", o.warning_degC, kWarningColour));
  if (std::isfinite(o.trip_degC))
    add(fmt::format("{} with lines lc rgb '{}' dt 4 notitle", o.trip_degC, kTripColour));
  return lines;
}

/// The error panel's half height, K: the errors all but their largest 0.5 % (a filter's first
/// seconds) and the widest node's typical (median) +-2 sd band, whichever is larger, plus a
/// margin: a filter that starts cold has a band of 15 K for its first minute, which would leave
/// errors well under 1 K after it a flat line.
double ErrorRange_K(std::vector<double> abs_errors, std::vector<double> node_median_2sd) {
  double e = 0.0;
  if (!abs_errors.empty()) {
    const auto k = static_cast<std::size_t>(0.995 * static_cast<double>(abs_errors.size() - 1));
    std::nth_element(abs_errors.begin(), abs_errors.begin() + static_cast<long>(k),
                     abs_errors.end());
    e = abs_errors[k];
  }
  const double band = node_median_2sd.empty()
                          ? 0.0
                          : *std::max_element(node_median_2sd.begin(), node_median_2sd.end());
  return std::max({1.2 * e, 1.2 * band, 0.1});
}

/// The plot lines of one pump's error panel (estimate minus truth at the estimate's times, the
/// +-2 sd band about zero; the extras minus the truth of their node); "" without both files.
/// `range_K` gets the panel's half height (ErrorRange_K).
std::string ErrorLines(const Series& s, std::size_t i, const TimeAxis& axis, const PlotOptions& o,
                       Figure& fig, double& range_K) {
  if (!s.truth || !s.estimate) return "";
  const CsvTable& tr = *s.truth;
  const CsvTable& est = *s.estimate;
  const std::vector<double> t_est = Times(est, axis), t_tr = Times(tr, axis);
  std::vector<std::vector<double>> cols{Minutes(t_est)};
  struct Curve {
    std::size_t col, colour;
    bool band, points;
  };
  std::vector<Curve> curves;
  std::vector<double> abs_errors, median_2sd;
  auto keep = [&](const std::vector<double>& e) {
    for (double v : e)
      if (std::isfinite(v)) abs_errors.push_back(std::abs(v));
  };
  auto truth_at = [&](const std::string& node) {
    return Interpolate(t_tr, Col(tr, node + "_degC"), t_est);
  };
  for (std::size_t k = 0; k < fig.nodes.size(); ++k) {
    const std::string& n = fig.nodes[k];
    if (!tr.Has(n + "_degC") || !est.Has(n + "_degC")) continue;
    const auto x = Col(est, n + "_degC");
    const auto truth = truth_at(n);
    std::vector<double> e(x.size());
    for (std::size_t r = 0; r < x.size(); ++r) e[r] = x[r] - truth[r];
    keep(e);
    cols.push_back(std::move(e));
    curves.push_back({cols.size() - 1, k, false, false});
    if (!o.no_bands && est.Has(n + "_sd_K")) {
      const auto sd = Col(est, n + "_sd_K");
      std::vector<double> finite;
      for (double v : sd)
        if (std::isfinite(v)) finite.push_back(2.0 * v);
      if (!finite.empty()) {
        std::nth_element(finite.begin(), finite.begin() + static_cast<long>(finite.size() / 2),
                         finite.end());
        median_2sd.push_back(finite[finite.size() / 2]);
      }
      std::vector<double> lo(sd.size()), hi(sd.size());
      for (std::size_t r = 0; r < sd.size(); ++r) {
        lo[r] = -2.0 * sd[r];
        hi[r] = 2.0 * sd[r];
      }
      cols.push_back(std::move(lo));
      cols.push_back(std::move(hi));
      curves.push_back({cols.size() - 2, k, true, false});
    }
  }
  for (const auto& [column, colour] : fig.extras) {
    if (colour == 0) continue;
    const std::string& n = fig.nodes[colour - 1];
    if (!tr.Has(n + "_degC")) continue;
    const auto x = Col(est, column);
    if (!AnyFinite(x)) continue;
    const auto truth = truth_at(n);
    std::vector<double> e(x.size());
    for (std::size_t r = 0; r < x.size(); ++r) e[r] = x[r] - truth[r];
    keep(e);
    cols.push_back(std::move(e));
    curves.push_back({cols.size() - 1, colour - 1, false, true});
  }
  if (curves.empty()) return "";
  range_K = ErrorRange_K(std::move(abs_errors), std::move(median_2sd));
  fig.any_error = true;
  const fs::path file = fig.dir / fmt::format("p{}_error.dat", i);
  WriteData(file, cols);
  std::string lines;
  // Bands first, under the lines; as their edges (thin, dotted), so that the nested bands of
  // the nodes stay apart.
  for (const Curve& c : curves)
    if (c.band)
      for (std::size_t edge : {c.col + 1, c.col + 2})
        lines += fmt::format("{}{} using 1:{} with lines lc rgb '{}' dt 3 lw 1 notitle",
                             lines.empty() ? "" : ", ", Quote(file.string()), edge,
                             NodeColour(c.colour));
  for (const Curve& c : curves)
    if (!c.band)
      lines += fmt::format("{}{} using 1:{} with {} lc rgb '{}' notitle", lines.empty() ? "" : ", ",
                           Quote(file.string()), c.col + 1,
                           c.points ? "points pt 7 ps 0.3" : "lines lw 1.5", NodeColour(c.colour));
  return lines + ", 0 with lines lc rgb '#000000' lw 0.8 notitle";
}

/// gnuplot commands drawing `marks` as vertical lines, and the line of text that names them
/// (in minutes, the axis' unit) in the panel's top left corner: lines are not labelled one by
/// one, so labels of moments a few seconds apart never overlap.
std::string MarkCommands(const std::vector<Mark>& marks, bool with_text) {
  std::string out = "unset arrow\nunset label\n";
  std::string text;
  for (const Mark& m : marks) {
    if (!std::isfinite(m.t_s)) continue;
    out += fmt::format(
        "set arrow from {0},graph 0 to {0},graph 1 nohead lc rgb '{1}' dt {2} lw 1.5 front\n",
        m.t_s / 60.0, m.colour, m.dash);
    std::string line = fmt::format("{} {}", MinutesText(m.t_s), m.text);
    std::string escaped;  // a double-quoted gnuplot string: \n breaks the line
    for (char c : line) {
      if (c == '"' || c == '\\') escaped += '\\';
      escaped += c;
    }
    text += (text.empty() ? "" : "\\n") + escaped;
  }
  if (with_text && !text.empty())
    out += fmt::format(
        "set label {} at graph 0.01,graph 0.95 left front font ',9' boxed textcolor rgb "
        "'#222222'\n",
        "\"" + text + "\"");
  return out;
}

/// The moments of one pump in time order: faults, diagnosis, alarms, the truth's crossings.
std::vector<Mark> PumpMarks(const Series& s) {
  std::vector<Mark> m = s.marks;
  auto add = [&](double t, std::string text, const char* colour, int dash) {
    if (std::isfinite(t)) m.push_back({t, std::move(text), colour, dash});
  };
  add(s.first_warning_s, "warning", kWarningColour, 1);
  add(s.first_trip_s, "trip", kTripColour, 1);
  add(s.truth_warning_s, "truth reaches the warning level", kWarningColour, 3);
  add(s.truth_trip_s, "truth reaches the trip level", kTripColour, 3);
  std::stable_sort(m.begin(), m.end(), [](const Mark& a, const Mark& b) { return a.t_s < b.t_s; });
  return m;
}

/// The figure's one legend: every node's colour, the line styles, the points and marks that are
/// drawn somewhere in the figure (nothing that is not).
std::string LegendPlot(const PlotOptions& o, const Figure& fig) {
  std::vector<std::string> e;
  for (std::size_t k = 0; k < fig.nodes.size(); ++k)
    e.push_back(fmt::format("keyentry with lines lc rgb '{}' lw 2.5 title {}", NodeColour(k),
                            Quote(fig.nodes[k])));
  if (fig.any_truth)
    e.push_back("keyentry with lines lc rgb '#444444' dt 1 lw 2.5 title 'truth (solid)'");
  if (fig.any_estimate)
    e.push_back(fmt::format("keyentry with lines lc rgb '#444444' dt 2 lw 1.5 title {}",
                            Quote(o.estimate_name + " (dashed)")));
  if (fig.any_band)
    e.push_back(
        "keyentry with filledcurves lc rgb '#444444' fs transparent solid 0.25 noborder title "
        "'+-2 sd band (dotted in error panels)'");
  for (std::size_t c = 0; c < fig.extras.size(); ++c) {
    if (!fig.extra_drawn[c]) continue;
    const std::size_t colour = fig.extras[c].second;
    e.push_back(fmt::format("keyentry with points pt {} ps 0.8 lc rgb '{}' title {}",
                            c % 2 == 0 ? 7 : 5, colour == 0 ? "black" : NodeColour(colour - 1),
                            Quote(ReadableName(fig.extras[c].first) + " (points)")));
  }
  if (std::isfinite(o.warning_degC))
    e.push_back(
        fmt::format("keyentry with lines lc rgb '{}' dt 4 title 'warning level'", kWarningColour));
  if (std::isfinite(o.trip_degC))
    e.push_back(
        fmt::format("keyentry with lines lc rgb '{}' dt 4 title 'trip level'", kTripColour));
  if (fig.any_events) {
    e.push_back(
        fmt::format("keyentry with lines lc rgb '{}' lw 2 title 'first warning'", kWarningColour));
    e.push_back(
        fmt::format("keyentry with lines lc rgb '{}' lw 2 title 'first trip'", kTripColour));
  }
  if (std::isfinite(o.warning_degC))
    e.push_back(fmt::format(
        "keyentry with lines lc rgb '{}' dt 3 title 'the truth reaches a level (dotted)'",
        kTripColour));
  if (fig.any_fault)
    e.push_back(fmt::format("keyentry with lines lc rgb '{}' dt 4 title 'fault'", kFaultColour));
  if (fig.any_diagnosis)
    e.push_back(fmt::format("keyentry with lines lc rgb '{}' dt 2 title 'daemon diagnosis'",
                            kDiagnosisColour));
  std::string out =
      "unset arrow\nunset label\nunset title\nunset border\nunset tics\nunset xlabel\n"
      "unset ylabel\nunset grid\nset xrange [0:1]\nset yrange [0:1]\n"
      "set key center center horizontal maxcols 4 width 1 samplen 3\n"
      // gnuplot 5.4 asserts on a plot of key entries alone: one invisible line (y = 2, outside
      // the range) comes first.
      "plot 2 with lines lc rgb 'white' notitle";
  for (const std::string& entry : e) out += ", " + entry;
  return out +
         "\nset border\nset tics\nset grid\nset key off\nset xlabel 'time (min)'\n"
         "set yrange [*:*]\n";
}

/// The alarm timeline: every pump's level as a step line, the pumps in this panel's own key (its
/// lines are pumps, not nodes).
std::string TimelinePlot(const std::vector<Series>& series, const TimeAxis& axis,
                         const Figure& fig) {
  std::string lines;
  static constexpr std::array<const char*, 4> kPumpColours{"#222222", "#1f77b4", "#9467bd",
                                                           "#2ca02c"};
  for (std::size_t i = 0; i < series.size(); ++i) {
    if (!series[i].events) continue;
    const auto t = Times(*series[i].events, axis);
    std::vector<std::vector<double>> cols{Minutes(t),
                                          Codes(*series[i].events, "alarm_level", kLevelWords)};
    for (double& v : cols[1]) v += 0.06 * static_cast<double>(i);  // coincident steps apart
    if (!t.empty() && cols[0].back() < fig.t_max_min) {            // hold the last level to the end
      cols[0].push_back(fig.t_max_min);
      cols[1].push_back(cols[1].back());
    }
    const fs::path file = fig.dir / fmt::format("p{}_alarm.dat", i);
    WriteData(file, cols);
    const char* colour = kPumpColours[i % kPumpColours.size()];
    lines += fmt::format("{}{} using 1:2 with steps lw 2 lc rgb '{}' title {}",
                         lines.empty() ? "" : ", ", Quote(file.string()), colour,
                         Quote(series[i].label));
  }
  return "unset arrow\nunset label\nset key top left horizontal\n"
         "set title 'alarm level of each pump'\nunset ylabel\n"
         "set yrange [-0.3:2.9]\nset ytics ('normal' 0, 'warning' 1, 'trip' 2)\nplot " +
         lines + "\nset ytics autofreq\nset yrange [*:*]\nset key off\n";
}

void CheckCounts(const PlotOptions& o, std::size_t n) {
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
}

/// Nodes: given, or every <node>_degC column the truth and the estimate share (else the truth's).
std::vector<std::string> ChooseNodes(const PlotOptions& o, const std::vector<Series>& series) {
  std::vector<std::string> nodes = o.nodes;
  if (nodes.empty()) {
    const CsvTable& ref = series[0].truth ? *series[0].truth : *series[0].estimate;
    for (const std::string& c : ref.columns()) {
      const std::size_t suffix = c.ends_with("_degC") ? 5 : c.ends_with("_C") ? 2 : 0;
      if (suffix == 0 || c == "ambient_C" || c == "ambient_degC") continue;
      if (series[0].truth && series[0].estimate && !series[0].estimate->Has(c)) continue;
      nodes.push_back(c.substr(0, c.size() - suffix));
    }
    if (nodes.empty())
      throw InputError(
          fmt::format("{}: no <node>_degC columns to plot; give --nodes", ref.source()));
  }
  for (const Series& s : series) {
    for (const std::string& node : nodes) {
      const bool in_truth = s.truth && s.truth->Has(node + "_degC");
      const bool in_est = s.estimate && s.estimate->Has(node + "_degC");
      if (!in_truth && !in_est) {
        throw InputError(fmt::format("column '{}_degC' is in neither {} nor {}", node,
                                     s.truth ? s.truth->source() : "(no truth)",
                                     s.estimate ? s.estimate->source() : "(no estimate)"));
      }
    }
  }
  return nodes;
}

void RunGnuplot(const PlotOptions& o, const std::string& script, const fs::path& dir) {
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
}

int RunPlot(const PlotOptions& o) {
  if (o.truth.empty() && o.estimate.empty())
    throw InputError("give --truth and/or --estimate CSV files");
  const std::size_t n = std::max(o.truth.size(), o.estimate.size());
  CheckCounts(o, n);
  const std::vector<Mark> user_marks = UserMarks(o.marks);

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

  Figure fig;
  fig.nodes = ChooseNodes(o, series);
  fig.dir = fs::temp_directory_path() / fmt::format("pumptherm-plot-{}", getpid());
  fs::create_directories(fig.dir);
  struct Cleanup {
    fs::path d;
    bool keep;
    ~Cleanup() {
      std::error_code ec;
      if (!keep) fs::remove_all(d, ec);
    }
  } cleanup{fig.dir, o.keep_script};

  // Extra estimate columns: (column, colour index: 1 + the node's position, else 0 = black).
  for (const std::string& e : o.extras) {
    const std::size_t eq = e.find('=');
    const std::string column = e.substr(0, eq);
    const std::string node = eq == std::string::npos ? "" : e.substr(eq + 1);
    const auto it = std::find(fig.nodes.begin(), fig.nodes.end(), node);
    fig.extras.emplace_back(
        column, it == fig.nodes.end() ? 0 : 1 + static_cast<std::size_t>(it - fig.nodes.begin()));
    for (const Series& s : series) {
      if (s.estimate && !s.estimate->Has(column)) {
        throw InputError(
            fmt::format("--extra: column '{}' is not in {}", column, s.estimate->source()));
      }
    }
  }
  fig.extra_drawn.assign(fig.extras.size(), false);

  const std::string level_node = !o.level_node.empty() ? o.level_node : fig.nodes[0];
  for (Series& s : series) {
    fig.any_truth = fig.any_truth || s.truth.has_value();
    fig.any_estimate = fig.any_estimate || s.estimate.has_value();
    if (s.truth) {
      AddFaultMarks(*s.truth, axis, s.marks);
      if (std::isfinite(o.warning_degC) && s.truth->Has(level_node + "_degC")) {
        const auto t = Times(*s.truth, axis);
        const auto v = Col(*s.truth, level_node + "_degC");
        s.truth_warning_s = FirstAtOrAbove(t, v, o.warning_degC);
        if (std::isfinite(o.trip_degC)) s.truth_trip_s = FirstAtOrAbove(t, v, o.trip_degC);
      }
    }
    const std::size_t faults = s.marks.size();
    if (s.estimate) AddDiagnosisMarks(*s.estimate, axis, s.marks);
    fig.any_fault = fig.any_fault || faults > 0 || !user_marks.empty();
    fig.any_diagnosis = fig.any_diagnosis || s.marks.size() > faults;
    s.marks.insert(s.marks.end(), user_marks.begin(), user_marks.end());
    if (s.events) {
      fig.any_events = true;
      const auto t = Times(*s.events, axis);
      const auto level = Codes(*s.events, "alarm_level", kLevelWords);
      s.first_warning_s = FirstAtOrAbove(t, level, 1.0);
      s.first_trip_s = FirstAtOrAbove(t, level, 2.0);
    }
    if (s.estimate)
      for (std::size_t c = 0; c < fig.extras.size(); ++c)
        fig.extra_drawn[c] = fig.extra_drawn[c] || AnyFinite(Col(*s.estimate, fig.extras[c].first));
  }

  // Panels: per pump its temperatures and (with truth and estimate) the estimate's error.
  struct Panel {
    std::string commands;
    double height;
  };
  std::vector<Panel> panels;
  for (std::size_t i = 0; i < n; ++i) {
    const Series& s = series[i];
    const std::vector<Mark> marks = PumpMarks(s);
    std::string missing;
    for (std::size_t c = 0; c < fig.extras.size(); ++c)
      if (s.estimate && !AnyFinite(Col(*s.estimate, fig.extras[c].first)))
        missing += (missing.empty() ? "" : ", ") + ReadableName(fig.extras[c].first);
    std::string cmd = MarkCommands(marks, true);
    if (!missing.empty())
      cmd += fmt::format(
          "set label {} at graph 0.99,graph 0.05 right front font ',9' tc rgb "
          "'#555555'\n",
          Quote(missing + ": not available"));
    cmd += fmt::format("set title {}\nset ylabel 'temperature (degC)'\nplot {}\n", Quote(s.label),
                       TemperatureLines(s, i, axis, o, fig));
    panels.push_back({cmd, 1.0});
    if (o.no_errors) continue;
    double range_K = 1.0;
    const std::string err = ErrorLines(s, i, axis, o, fig, range_K);
    if (err.empty()) continue;
    panels.push_back(
        {MarkCommands(marks, false) +
             fmt::format("set title {}\nset ylabel 'error (K)'\nset yrange [{}:{}]\nplot {}\n"
                         "set yrange [*:*]\n",
                         Quote(s.label + ": " + o.estimate_name + " minus truth"), -range_K,
                         range_K, err),
         0.6});
  }
  if (fig.any_events) panels.push_back({TimelinePlot(series, axis, fig), 0.55});

  const double legend_px = 100.0, title_px = 30.0;
  double rows_px = 0.0;
  for (const Panel& p : panels) rows_px += p.height * o.row_height_px;
  const double height = rows_px + legend_px + title_px;
  const std::string ext = fs::path(o.out).extension().string();
  std::string script;
  if (ext == ".png") {
    script += fmt::format("set terminal pngcairo size {},{:.0f} font 'sans,10' noenhanced\n",
                          o.width_px, height);
  } else {
    script += fmt::format("set terminal svg size {},{:.0f} dynamic font 'sans,10' noenhanced\n",
                          o.width_px, height);
  }
  script += fmt::format("set output {}\n", Quote(fs::absolute(o.out).string()));
  script += fmt::format("set multiplot title {}\n", Quote(o.title));
  // Fixed margins so the panels' time axes line up whatever the tick labels.
  script += fmt::format(
      "set grid\nset xlabel 'time (min)'\nset xrange [0:{}]\n"
      "set lmargin at screen 0.07\nset rmargin at screen 0.93\n",
      fig.t_max_min);
  double top = 1.0 - title_px / height;
  script += fmt::format("set origin 0,{:.5f}\nset size 1,{:.5f}\n", top - legend_px / height,
                        legend_px / height);
  script += LegendPlot(o, fig) + fmt::format("set xrange [0:{}]\n", fig.t_max_min);
  top -= legend_px / height;
  for (const Panel& p : panels) {
    const double h = p.height * o.row_height_px / height;
    top -= h;
    script += fmt::format("set origin 0,{:.5f}\nset size 1,{:.5f}\n{}", std::max(top, 0.0), h,
                          p.commands);
  }
  script += "unset multiplot\n";
  RunGnuplot(o, script, fig.dir);
  if (o.keep_script) fmt::print(stderr, "gnuplot script and data kept in {}\n", fig.dir.string());
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

const SubcommandRegistrar kPlotRegistrar{
    "plot",
    "Plot estimated against true temperatures, the estimate's error and the alarm timeline "
    "(PNG/SVG via gnuplot)",
    [](CLI::App& app) -> std::function<int()> {
      auto o = std::make_shared<PlotOptions>();
      app.add_option("--truth,-t", o->truth,
                     "Truth CSV per pump (time_s, <node>_degC), e.g. from `pumptherm plant`");
      app.add_option("--estimate,-e", o->estimate,
                     "Estimate CSV per pump (time_s, <node>_degC, <node>_sd_K; alarm_level and "
                     "mismatch_state if present)");
      app.add_option(
          "--events", o->events,
          "CSV per pump with time_s and alarm_level (normal, warning, trip or 0, 1, 2); default: "
          "the estimate CSV when it has alarm_level");
      app.add_option("--label", o->labels, "Panel title per pump (default: the file name)");
      app.add_option("--nodes,-n", o->nodes,
                     "Nodes to plot (default: every <node>_degC column both files have)")
          ->delimiter(',');
      app.add_option(
             "--extra", o->extras,
             "Estimate columns drawn as points, COLUMN or COLUMN=NODE (in that node's colour, and "
             "their error against that node's truth), e.g. "
             "winding_resistance_degC=winding,magnet_flux_degC=rotor")
          ->delimiter(',');
      app.add_option("--mark", o->marks,
                     "A moment to mark on every panel, SECONDS=TEXT (e.g. 240=cooling fails); the "
                     "truth's cooling failures are marked without it");
      app.add_flag("--no-bands", o->no_bands,
                   "Do not draw the +-2 sd bands of the estimate's <node>_sd_K");
      app.add_flag("--no-errors", o->no_errors, "Do not draw the estimate-minus-truth panels");
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
      app.add_option("--row-height", o->row_height_px,
                     "Height of a temperature panel in pixels (an error panel: 0.6 of it)")
          ->capture_default_str();
      app.add_option("--gnuplot", o->gnuplot, "gnuplot executable")->capture_default_str();
      app.add_flag("--keep-script", o->keep_script,
                   "Keep the generated gnuplot script and data files");
      app.add_option(
          "--time-origin", o->time_origin_s,
          "Unix time (s) drawn as t = 0 for files whose time_s is Unix time (the daemon's CSV "
          "with --csv-time-origin 0), e.g. the recording's first timestamp; default: the "
          "earliest such file's first whole second");
      app.footer(
          "Example:\n"
          "  pumptherm plot --truth out/pump3.truth.csv --estimate est3.csv --nodes winding,frame "
          "\\\n"
          "      --warning-C 100 --trip-C 120 --out pump3.png\n"
          "Per pump (repeat --truth/--estimate/--label in the same order) a temperature panel "
          "and,\n"
          "with truth and estimate, an error panel (estimate minus truth, its +-2 sd band about 0\n"
          "as dotted edges);\n"
          "then the alarm timeline. One legend at the top. Vertical lines: the truth's cooling\n"
          "failures, the daemon's diagnosis (mismatch_state), the first warning and trip (solid)\n"
          "and the truth's level crossings (dotted), listed in minutes in each panel's corner.\n"
          "Time: a file whose time_s is Unix time (pumpthermd --csv-time-origin 0) is put on the "
          "axis of "
          "the\n"
          "relative files (plant, estimate) by --time-origin; standard error says, per file, how.");
      return [o] { return RunPlot(*o); };
    }};

}  // namespace
}  // namespace pumptherm::tools
