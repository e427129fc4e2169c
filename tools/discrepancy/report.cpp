#include "tools/discrepancy/report.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <system_error>
#include <utility>

#include "estimators/model_effects.hpp"

namespace pumptherm::tools::discrepancy {
namespace {

std::string Str(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (static_cast<unsigned char>(c) < 0x20) {
      out += fmt::format("\\u{:04x}", static_cast<int>(static_cast<unsigned char>(c)));
    } else {
      out += c;
    }
  }
  return out + "\"";
}

std::string Num(double v) { return std::isfinite(v) ? fmt::format("{:.6g}", v) : "null"; }

std::string Html(const std::string& s) {
  std::string out;
  for (char c : s) {
    if (c == '<')
      out += "&lt;";
    else if (c == '>')
      out += "&gt;";
    else if (c == '&')
      out += "&amp;";
    else
      out += c;
  }
  return out;
}

std::string Params(const std::vector<FittedParameter>& ps) {
  std::string out = "[";
  for (std::size_t i = 0; i < ps.size(); ++i)
    out += fmt::format("{}{{\"name\": {}, \"value\": {}, \"ci95\": [{}, {}], \"neutral\": {}}}",
                       i ? ", " : "", Str(ps[i].name), Num(ps[i].value), Num(ps[i].low95),
                       Num(ps[i].high95), Num(ps[i].neutral));
  return out + "]";
}

std::string Gap(const std::vector<NodeGap>& g) {
  std::string out = "{";
  for (std::size_t i = 0; i < g.size(); ++i)
    out += fmt::format("{}{}: {{\"rmse_K\": {}, \"max_abs_K\": {}}}", i ? ", " : "", Str(g[i].node),
                       Num(g[i].rmse_K), Num(g[i].max_abs_K));
  return out + "}";
}

std::string CandidateJson(const Candidate& c) {
  if (!c.not_applicable.empty())
    return fmt::format("{{\"name\": {}, \"tried\": false, \"reason\": {}}}", Str(c.label),
                       Str(c.not_applicable));
  return fmt::format(
      "{{\"name\": {}, \"effect\": {}, \"node\": {}, \"tried\": true, \"score\": "
      "{{\"validate_rmse_K\": {}, "
      "\"train_rmse_K\": {}, \"delta_ic\": {}, \"rho\": {}, \"n_eff\": {}}}, \"significant\": {}, "
      "\"eligible\": {}, \"parameters\": {}, \"evaluations\": {}}}",
      Str(c.label), Str(c.effect), c.node.empty() ? "null" : Str(c.node), Num(c.validate_rmse_K),
      Num(c.train_rmse_K), Num(c.delta_ic), Num(c.rho), Num(c.n_eff),
      c.significant ? "true" : "false", c.eligible ? "true" : "false", Params(c.parameters),
      c.evaluations);
}

/// Tick values at 1, 2 or 5 x 10^k, about `n` intervals, the first at or below `lo` and the
/// last at or above `hi` (the axis spans them).
std::vector<double> NiceTicks(double lo, double hi, int n) {
  if (!(hi > lo)) hi = lo + 1.0;
  const double raw = (hi - lo) / n;
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  double step = 10.0 * mag;
  for (double m : {1.0, 2.0, 5.0})
    if (m * mag >= raw) {
      step = m * mag;
      break;
    }
  std::vector<double> t;
  const double first = std::floor(lo / step + 1e-9), last = std::ceil(hi / step - 1e-9);
  for (double k = first; k <= last; k += 1.0) t.push_back(k * step == 0.0 ? 0.0 : k * step);
  return t;
}

/// A tick label with the decimals the tick step needs.
std::string TickLabel(double v, const std::vector<double>& ticks) {
  const double step = ticks.size() > 1 ? ticks[1] - ticks[0] : 1.0;
  const int dec = std::clamp(static_cast<int>(-std::floor(std::log10(step) + 1e-9)), 0, 9);
  return fmt::format("{:.{}f}", std::abs(v) < 1e-9 * step ? 0.0 : v, dec);
}

/// One series of a plot; drawn in order, so the last is on top.
struct Line {
  std::string name, colour;
  const std::vector<double>* y;
  bool dashed = false;
  double width = 1.2;
};

/// Plot frame in SVG user units; the SVG scales to the page's width.
struct Frame {
  double w = 960, h = 260, l = 64, r = 120, top = 24, b = 38;
};

/// Axes with round ticks and a grid; returns the SVG text up to the data, and the mappings.
struct Axes {
  Frame f;
  std::vector<double> xt, yt;
  double X(double x) const {
    return f.l + (f.w - f.l - f.r) * (x - xt.front()) / (xt.back() - xt.front());
  }
  double Y(double y) const {
    return f.top + (f.h - f.top - f.b) * (yt.back() - y) / (yt.back() - yt.front());
  }
};

std::string AxesSvg(const Axes& a, const std::string& title, const std::string& xlabel,
                    const std::string& ylabel, bool zero_line) {
  const Frame& f = a.f;
  std::string s = fmt::format(
      "<svg xmlns='http://www.w3.org/2000/svg' viewBox='0 0 {} {}' width='100%' "
      "font-family='sans-serif' "
      "font-size='12'><rect width='100%' height='100%' fill='white'/><text x='{}' y='16' "
      "font-size='14'>{}"
      "</text>",
      f.w, f.h, f.l, Html(title));
  for (double y : a.yt)
    s += fmt::format(
        "<line x1='{}' x2='{}' y1='{:.1f}' y2='{:.1f}' stroke='#e4e4e4'/><text x='{}' y='{:.1f}' "
        "text-anchor='end'>{}</text>",
        f.l, f.w - f.r, a.Y(y), a.Y(y), f.l - 4, a.Y(y) + 4, TickLabel(y, a.yt));
  for (double x : a.xt)
    s += fmt::format(
        "<line x1='{:.1f}' x2='{:.1f}' y1='{}' y2='{}' stroke='#e4e4e4'/><text x='{:.1f}' y='{}' "
        "text-anchor='middle'>{}</text>",
        a.X(x), a.X(x), f.top, f.h - f.b, a.X(x), f.h - f.b + 15, TickLabel(x, a.xt));
  if (zero_line && a.yt.front() < 0.0 && a.yt.back() > 0.0)
    s += fmt::format(
        "<line x1='{}' x2='{}' y1='{:.1f}' y2='{:.1f}' stroke='#000' stroke-width='0.8'/>", f.l,
        f.w - f.r, a.Y(0.0), a.Y(0.0));
  s += fmt::format("<rect x='{}' y='{}' width='{}' height='{}' fill='none' stroke='#666'/>", f.l,
                   f.top, f.w - f.l - f.r, f.h - f.top - f.b);
  s += fmt::format("<text x='{}' y='{}' text-anchor='middle'>{}</text>",
                   f.l + (f.w - f.l - f.r) / 2, f.h - 4, Html(xlabel));
  return s +
         fmt::format(
             "<text x='14' y='{0}' transform='rotate(-90 14 {0})' text-anchor='middle'>{1}</text>",
             f.top + (f.h - f.top - f.b) / 2, Html(ylabel));
}

/// A line plot against time in hours, one polyline per series (at most about 1000 points each).
std::string Svg(const std::string& title, const std::vector<double>& t_s,
                const std::vector<Line>& lines, const std::string& ylabel, bool zero_line = false,
                double height = 260) {
  double ymin = 1e300, ymax = -1e300;
  for (const Line& ln : lines)
    for (double v : *ln.y)
      if (std::isfinite(v)) {
        ymin = std::min(ymin, v);
        ymax = std::max(ymax, v);
      }
  if (ymin > ymax) ymin = ymax = 0.0;
  if (zero_line) {
    ymin = std::min(ymin, 0.0);
    ymax = std::max(ymax, 0.0);
  }
  Axes a;
  a.f.h = height;
  a.yt = NiceTicks(ymin, ymax, height < 200 ? 3 : 6);
  a.xt = NiceTicks(t_s.front() / 3600.0, std::max(t_s.back(), t_s.front() + 1.0) / 3600.0, 8);
  std::string s = AxesSvg(a, title, "time, h", ylabel, zero_line);
  int k = 0;
  for (const Line& ln : lines) {
    std::string pts;
    const std::size_t n = std::min(t_s.size(), ln.y->size());
    const std::size_t stride = std::max<std::size_t>(1, n / 1000);
    for (std::size_t j = 0; j < n; j += stride)
      if (std::isfinite((*ln.y)[j]))
        pts += fmt::format("{:.1f},{:.1f} ", a.X(t_s[j] / 3600.0), a.Y((*ln.y)[j]));
    s += fmt::format("<polyline fill='none' stroke='{}' stroke-width='{}'{} points='{}'/>",
                     ln.colour, ln.width, ln.dashed ? " stroke-dasharray='5 3'" : "", pts);
    const double ly = a.f.top + 10 + 15 * k;
    s += fmt::format(
        "<line x1='{}' x2='{}' y1='{}' y2='{}' stroke='{}' stroke-width='{}'{}/><text x='{}' "
        "y='{}'>"
        "{}</text>",
        a.f.w - a.f.r + 8, a.f.w - a.f.r + 30, ly, ly, ln.colour, ln.width,
        ln.dashed ? " stroke-dasharray='5 3'" : "", a.f.w - a.f.r + 34, ly + 4, Html(ln.name));
    ++k;
  }
  return s + "</svg>";
}

/// Correlation against lag as stems, with the 95 % band +/- `band` (dashed) and a zero line.
std::string CorrSvg(const std::string& title, const std::vector<double>& lag,
                    const std::vector<double>& c, double band, const std::string& xlabel) {
  Axes a;
  a.f = Frame{320, 220, 46, 10, 24, 38};
  a.yt = NiceTicks(-1.0, 1.0, 4);
  a.xt = NiceTicks(lag.front(), lag.back(), 4);
  std::string s = AxesSvg(a, title, xlabel, "correlation", true);
  for (double b : {band, -band})
    s += fmt::format(
        "<line x1='{}' x2='{}' y1='{:.1f}' y2='{:.1f}' stroke='#d62728' stroke-dasharray='5 3'/>",
        a.f.l, a.f.w - a.f.r, a.Y(b), a.Y(b));
  for (std::size_t i = 0; i < lag.size(); ++i)
    s += fmt::format("<line x1='{0:.1f}' x2='{0:.1f}' y1='{1:.1f}' y2='{2:.1f}' stroke='#1f77b4'/>",
                     a.X(lag[i]), a.Y(0.0), a.Y(std::clamp(c[i], -1.0, 1.0)));
  return s + "</svg>";
}

/// Normalised cross-correlation r_xy(k) = sum_t x'(t+k) y'(t) / sqrt(sum x'^2 sum y'^2), x' and
/// y' with their means removed, for k = -max_lag..max_lag (x = y gives the autocorrelation).
std::vector<double> CrossCorrelation(const std::vector<double>& x, const std::vector<double>& y,
                                     int max_lag) {
  const std::size_t n = std::min(x.size(), y.size());
  double mx = 0, my = 0;
  for (std::size_t t = 0; t < n; ++t) {
    mx += x[t];
    my += y[t];
  }
  mx /= n;
  my /= n;
  double sxx = 0, syy = 0;
  for (std::size_t t = 0; t < n; ++t) {
    sxx += (x[t] - mx) * (x[t] - mx);
    syy += (y[t] - my) * (y[t] - my);
  }
  const double norm = std::sqrt(sxx * syy);
  std::vector<double> r;
  for (int k = -max_lag; k <= max_lag; ++k) {
    double sum = 0;
    for (std::size_t t = 0; t < n; ++t) {
      const long tk = static_cast<long>(t) + k;
      if (tk >= 0 && tk < static_cast<long>(n)) sum += (x[tk] - mx) * (y[t] - my);
    }
    r.push_back(norm > 0 ? sum / norm : 0.0);
  }
  return r;
}

/// The validation inputs averaged over each plot grid step (t_{k-1}, t_k]: speed, and the
/// current amplitude as rms of sqrt(id^2 + iq^2) (so its square keeps the copper loss).
void InputsOnGrid(const Data& d, const std::vector<double>& grid_s, std::vector<double>& speed_rpm,
                  std::vector<double>& current_A) {
  speed_rpm.assign(grid_s.size(), std::nan(""));
  current_A.assign(grid_s.size(), std::nan(""));
  std::size_t j = 0;
  for (std::size_t k = 0; k < grid_s.size(); ++k) {
    double n = 0, sp = 0, i2 = 0;
    for (; j < d.size() && d.time_s[j] <= grid_s[k]; ++j) {
      sp += d.speed_rpm[j];
      i2 += d.id_A[j] * d.id_A[j] + d.iq_A[j] * d.iq_A[j];
      ++n;
    }
    if (n > 0) {
      speed_rpm[k] = sp / n;
      current_A[k] = std::sqrt(i2 / n);
    } else if (k > 0) {
      speed_rpm[k] = speed_rpm[k - 1];
      current_A[k] = current_A[k - 1];
    }
  }
  for (std::size_t k = grid_s.size(); k-- > 1;)  // grid points before the first sample
    if (std::isnan(speed_rpm[k - 1])) {
      speed_rpm[k - 1] = speed_rpm[k];
      current_A[k - 1] = current_A[k];
    }
}

/// The unit of an effect parameter, read from its name's suffix ("" = dimensionless).
std::string UnitOf(const std::string& name) {
  const std::string base = name.substr(0, name.find("__"));  // sensor parameters: <name>__<node>
  auto ends = [&](const char* s) {
    const std::string suf(s);
    return base.size() >= suf.size() &&
           base.compare(base.size() - suf.size(), suf.size(), suf) == 0;
  };
  if (ends("_J_per_K")) return "J/K";
  if (ends("_W_per_krpm2")) return "W/(1000 r/min)^2";
  if (ends("_per_krpm")) return "per 1000 r/min";
  if (ends("_per_K")) return "1/K";
  if (ends("_K")) return "K";
  if (ends("_s")) return "s";
  return "1 (a factor)";
}

/// "value (95 % low to high) unit" with the decimals that show the interval's width to three
/// significant figures (four significant figures of the value when the width is 0 or unknown).
std::string ValueWithInterval(const FittedParameter& p) {
  const double width = std::abs(p.high95 - p.low95);
  const double scale = width > 0 && std::isfinite(width) ? width : std::abs(p.value);
  const int dec =
      std::clamp(scale > 0 ? 2 - static_cast<int>(std::floor(std::log10(scale))) : 3, 0, 12);
  const std::string unit = UnitOf(p.name);
  return fmt::format("{:.{}f} (95 % {:.{}f} to {:.{}f}){}", p.value, dec, p.low95, dec, p.high95,
                     dec, unit.rfind("1 ", 0) == 0 ? "" : " " + unit);
}

/// Why a tried candidate was not named in its round: every test of the decision rule it
/// failed, or, when eligible, what beat it.
std::string WhyNot(const Candidate& c, const Round& rd, const Options& o,
                   const std::string& named) {
  if (c.label == named) return "named";
  std::vector<std::string> why;
  if (!c.significant)
    why.push_back(
        fmt::format("not significant (interval includes {})", Num(c.parameters[0].neutral)));
  if (!(c.delta_ic <= -o.ic_threshold))
    why.push_back(fmt::format("dIC {:.1f} > -{}", c.delta_ic, o.ic_threshold));
  const double gain = 1.0 - c.validate_rmse_K / rd.base_validate_rmse_K;
  if (!(gain >= o.min_validation_gain))
    why.push_back(fmt::format("validation gain {:.1f} % < {:.0f} %", 100 * gain,
                              100 * o.min_validation_gain));
  if (const estimators::EffectSpec* spec = estimators::FindEffect(c.effect); spec != nullptr) {
    const auto& ps = spec->parameters.front();
    const double v = c.parameters[0].value, tol = 1e-6 * (ps.upper - ps.lower);
    if (v <= ps.lower + tol || v >= ps.upper - tol)
      why.push_back(fmt::format("at its physical bound ({})",
                                Num(v <= ps.lower + tol ? ps.lower : ps.upper)));
  }
  if (!why.empty()) {
    std::string out;
    for (const auto& w : why) out += (out.empty() ? "" : "; ") + w;
    return out;
  }
  if (std::find(rd.tied.begin(), rd.tied.end(), c.label) != rd.tied.end())
    return fmt::format("eligible; within the {:.0f} % margin of the best: cannot tell apart",
                       100 * o.margin);
  return named.empty() ? "eligible; not the best"
                       : "eligible; validation RMSE above " + named + "'s";
}

/// The model file's edit as a line diff (LCS) with two lines of context around each change.
std::string ModelEditHtml(const std::string& before, const std::string& after) {
  auto lines = [](const std::string& t) {
    std::vector<std::string> v;
    std::size_t p = 0;
    while (p < t.size()) {
      const std::size_t e = t.find('\n', p);
      v.push_back(t.substr(p, e == std::string::npos ? std::string::npos : e - p));
      p = e == std::string::npos ? t.size() : e + 1;
    }
    return v;
  };
  const std::vector<std::string> a = lines(before), b = lines(after);
  if (a.size() > 4000 || b.size() > 4000) return "<p>(model too long to show the edit here)</p>";
  std::vector<std::vector<int>> L(a.size() + 1, std::vector<int>(b.size() + 1, 0));
  for (std::size_t i = a.size(); i-- > 0;)
    for (std::size_t j = b.size(); j-- > 0;)
      L[i][j] = a[i] == b[j] ? L[i + 1][j + 1] + 1 : std::max(L[i + 1][j], L[i][j + 1]);
  std::vector<std::pair<char, std::string>> ops;  // ' ' same, '-' removed, '+' added
  std::size_t i = 0, j = 0;
  while (i < a.size() || j < b.size()) {
    if (i < a.size() && j < b.size() && a[i] == b[j]) {
      ops.emplace_back(' ', a[i++]);
      ++j;
    } else if (i < a.size() && (j == b.size() || L[i + 1][j] >= L[i][j + 1])) {
      ops.emplace_back('-', a[i++]);
    } else {
      ops.emplace_back('+', b[j++]);
    }
  }
  std::vector<bool> show(ops.size(), false);
  for (std::size_t k = 0; k < ops.size(); ++k)
    if (ops[k].first != ' ')
      for (std::size_t m = k > 2 ? k - 2 : 0; m < std::min(ops.size(), k + 3); ++m) show[m] = true;
  std::string h = "<pre class='diff'>";
  bool gap = false;
  for (std::size_t k = 0; k < ops.size(); ++k) {
    if (!show[k]) {
      gap = true;
      continue;
    }
    if (gap) h += "<span class='gap'>...</span>\n";
    gap = false;
    const char* cls = ops[k].first == '+' ? "add" : ops[k].first == '-' ? "del" : "ctx";
    h += fmt::format("<span class='{}'>{} {}</span>\n", cls, ops[k].first, Html(ops[k].second));
  }
  return h + "</pre>";
}

}  // namespace

std::string ReportJson(const Result& r, const std::string& model, const std::string& train,
                       const std::string& validate) {
  std::string j = "{\n";
  j += fmt::format("  \"model\": {},\n  \"train\": {},\n  \"validate\": {},\n", Str(model),
                   Str(train), Str(validate));
  j += fmt::format("  \"verdict\": {},\n", Str(r.verdict));
  j += fmt::format("  \"effect\": {},\n",
                   Str(r.effects.empty() ? "none" : r.effects.front().effect.name));
  j += "  \"effects\": [";
  for (std::size_t i = 0; i < r.effects.size(); ++i) {
    const AddedEffect& e = r.effects[i];
    j += fmt::format("{}\n    {{\"name\": {}, \"node\": {}, \"parameters\": {}, \"reading\": {}}}",
                     i ? "," : "", Str(e.effect.name),
                     e.effect.node.empty() ? "null" : Str(e.effect.node), Params(e.parameters),
                     Str(e.reading));
  }
  j += r.effects.empty() ? "],\n" : "\n  ],\n";
  // `candidates`: the first round's (every candidate against the input model); later rounds in
  // `rounds`.
  j += "  \"candidates\": [";
  if (!r.rounds.empty())
    for (std::size_t i = 0; i < r.rounds[0].candidates.size(); ++i)
      j += (i ? ",\n    " : "\n    ") + CandidateJson(r.rounds[0].candidates[i]);
  j += "\n  ],\n";
  const Round* amb = nullptr;
  for (const Round& rd : r.rounds)
    if (rd.verdict == "ambiguous") amb = &rd;
  j += "  \"ambiguous\": ";
  if (amb == nullptr) {
    j += "null,\n";
  } else {
    j += "{\"candidates\": [";
    for (std::size_t i = 0; i < amb->tied.size(); ++i) j += (i ? ", " : "") + Str(amb->tied[i]);
    j += fmt::format("], \"experiment\": {}}},\n", Str(amb->experiment));
  }
  j += "  \"rounds\": [";
  for (std::size_t i = 0; i < r.rounds.size(); ++i) {
    const Round& rd = r.rounds[i];
    j += fmt::format(
        "{}\n    {{\"verdict\": {}, \"base_train_rmse_K\": {}, \"base_validate_rmse_K\": {}, "
        "\"candidates\": [",
        i ? "," : "", Str(rd.verdict), Num(rd.base_train_rmse_K), Num(rd.base_validate_rmse_K));
    for (std::size_t c = 0; c < rd.candidates.size(); ++c)
      j += (c ? ",\n      " : "\n      ") + CandidateJson(rd.candidates[c]);
    j += "]}";
  }
  j += "\n  ],\n";
  j += fmt::format(
      "  \"gap\": {{\n    \"train\": {{\"before\": {}, \"after\": {}}},\n    \"validate\": "
      "{{\"before\": {}, "
      "\"after\": {}}}\n  }},\n",
      Gap(r.train_before), Gap(r.train_after), Gap(r.validate_before), Gap(r.validate_after));
  j += fmt::format(
      "  \"simulation\": {}, \"averaging_cost_K\": {{\"train\": {}, \"validate\": {}}},\n",
      Str(r.simulation), Num(r.averaging_cost_train_K), Num(r.averaging_cost_validate_K));
  j += fmt::format("  \"run_time_s\": {}\n}}\n", Num(r.seconds));
  return j;
}

namespace {

/// The label of the candidate a round named ("" when it named none): the best eligible one.
std::string NamedIn(const Round& rd) {
  if (rd.verdict != "named") return "";
  for (const Candidate& c : rd.candidates)
    if (c.not_applicable.empty() && c.eligible) return c.label;
  return "";
}

std::string RoundHtml(std::size_t index, const Round& rd, const Options& o) {
  std::string h =
      fmt::format("<h2>Round {}: {} (current model: train {:.3f} K, validate {:.3f} K)</h2>",
                  index + 1, Html(rd.verdict), rd.base_train_rmse_K, rd.base_validate_rmse_K);
  if (rd.verdict == "ambiguous") {
    h += "<p class='amb'>Cannot tell apart:";
    for (const auto& t : rd.tied) h += " <b>" + Html(t) + "</b>";
    h += "<br>Experiment that would separate them: " + Html(rd.experiment) + "</p>";
  }
  const std::string named = NamedIn(rd);
  h += "<table><tr><th>candidate</th><th>validate RMSE, K</th><th>train RMSE, K</th><th>dIC</th>"
       "<th>rho</th><th>n_eff</th><th>parameter = value (95 % interval) unit</th><th>eligible</th>"
       "<th>why not named</th></tr>";
  for (const Candidate& c : rd.candidates) {
    if (!c.not_applicable.empty()) {
      h += fmt::format("<tr><td>{}</td><td colspan='8' class='why'>not tried: {}</td></tr>",
                       Html(c.label), Html(c.not_applicable));
      continue;
    }
    const FittedParameter& p = c.parameters[0];
    h += fmt::format(
        "<tr><td>{}</td><td>{:.3f}</td><td>{:.3f}</td><td>{:.1f}</td><td>{:.3f}</td><td>{:.1f}"
        "</td><td class='val'>{} = {}</td><td>{}</td><td class='why'>{}</td></tr>",
        Html(c.label), c.validate_rmse_K, c.train_rmse_K, c.delta_ic, c.rho, c.n_eff, Html(p.name),
        Html(ValueWithInterval(p)), c.eligible ? "yes" : "no", Html(WhyNot(c, rd, o, named)));
  }
  return h + "</table>";
}

std::string CriterionHtml(const Options& o) {
  return fmt::format(
      "<p class='crit'>A candidate is <i>eligible</i> when all three hold: its information "
      "criterion "
      "dIC = n_eff ln(SSR/SSR<sub>current</sub>) + ln(n_eff) is at most -{} (lower is better; BIC "
      "at the "
      "effective sample size n_eff = n (1 - rho)/(1 + rho)); its 95 % interval excludes the "
      "neutral value "
      "(significant); and it cuts the current model's validation RMSE by at least {:.0f} %. Values "
      "at a "
      "physical bound are flagged. The best eligible one is <i>named</i> when every other "
      "candidate's "
      "validation RMSE is at least {:.2f} x its own, else the round is ambiguous "
      "(docs/discrepancy.md, How it decides).</p>",
      o.ic_threshold, 100 * o.min_validation_gain, 1.0 + o.margin);
}

/// Residual autocorrelation and cross-correlation with the inputs (speed, current), as
/// MATLAB's resid shows them. Bands: +/- 1.96/sqrt(N) for the autocorrelation (white residuals);
/// for the cross-correlation 1.96 sqrt(var), var = (1/N) sum_j r_ee(j) r_uu(j) over the plotted
/// lags: Bartlett's variance of a sample cross-correlation (Bartlett 1978, An Introduction to
/// Stochastic Processes, 3rd ed., p. 352) with the true cross-correlation zero, 1/(N - k) taken
/// as 1/N (lags at most N/4).
std::string CorrelationHtml(
    const std::string& node, const std::vector<double>& t_s, const std::vector<double>& res,
    const std::vector<std::pair<std::string, const std::vector<double>*>>& inputs) {
  const std::size_t n = res.size();
  if (n < 8) return "";
  const int max_lag = static_cast<int>(std::min<std::size_t>(40, n / 4));
  const double step_min = (t_s.back() - t_s.front()) / static_cast<double>(n - 1) / 60.0;
  std::vector<double> lag;
  for (int k = -max_lag; k <= max_lag; ++k) lag.push_back(k * step_min);
  const std::vector<double> ree = CrossCorrelation(res, res, max_lag);
  const std::vector<double> pos_lag(lag.begin() + max_lag, lag.end()),
      pos_ree(ree.begin() + max_lag, ree.end());
  const double sqrt_n = std::sqrt(static_cast<double>(n));
  std::string h = "<div class='row'>" + CorrSvg(node + ": residual autocorrelation", pos_lag,
                                                pos_ree, 1.96 / sqrt_n, "lag, min");
  for (const auto& [name, u] : inputs) {
    const std::vector<double> ruu = CrossCorrelation(*u, *u, max_lag);
    double var = 0;
    for (int k = 0; k < 2 * max_lag + 1; ++k) var += ree[k] * ruu[k];
    h += CorrSvg(node + ": residual x " + name, lag, CrossCorrelation(res, *u, max_lag),
                 1.96 * std::sqrt(std::max(var, 1.0)) / sqrt_n, "lag, min (input leads at +)");
  }
  return h + "</div>";
}

std::string PlotsHtml(const PlotSeries& v, const Data* data) {
  std::string h = "<h2>Validation data: measured against simulated</h2>";
  std::vector<double> speed, current;
  if (data != nullptr && data->size() > 0 && !v.time_s.empty())
    InputsOnGrid(*data, v.time_s, speed, current);
  for (std::size_t i = 0; i < v.nodes.size(); ++i) {
    h += "<h3>" + Html(v.nodes[i]) + "</h3>";
    h += Svg(v.nodes[i] + ": temperature", v.time_s,
             {{"before", "#d62728", &v.before[i], true, 1.4},
              {"after", "#1f77b4", &v.after[i], false, 2.4},
              {"measured", "#000", &v.measured[i], false, 1.0}},
             "degC");
    if (!speed.empty()) {
      h += Svg("input: speed", v.time_s, {{"speed", "#2ca02c", &speed}}, "r/min", false, 140);
      h += Svg("input: current amplitude (rms)", v.time_s, {{"current", "#9467bd", &current}}, "A",
               false, 140);
    }
    std::vector<double> rb(v.time_s.size()), ra(v.time_s.size());
    for (std::size_t j = 0; j < v.time_s.size(); ++j) {
      rb[j] = v.before[i][j] - v.measured[i][j];
      ra[j] = v.after[i][j] - v.measured[i][j];
    }
    h += Svg(v.nodes[i] + ": residual (simulated - measured)", v.time_s,
             {{"before", "#d62728", &rb, true, 1.4}, {"after", "#1f77b4", &ra, false, 1.4}}, "K",
             true);
    std::vector<std::pair<std::string, const std::vector<double>*>> inputs;
    if (!speed.empty()) inputs = {{"speed", &speed}, {"current", &current}};
    h += CorrelationHtml(v.nodes[i] + " after", v.time_s, ra, inputs);
  }
  return h;
}

std::string RankingHtml(const Round& rd) {
  std::string h =
      "<h2>Candidate ranking, round 1 (validation RMSE, K)</h2><svg "
      "xmlns='http://www.w3.org/2000/svg' "
      "width='640' font-family='sans-serif' font-size='11' height='" +
      std::to_string(20 + 16 * rd.candidates.size()) + "'>";
  double mx = rd.base_validate_rmse_K;
  for (const Candidate& c : rd.candidates) mx = std::max(mx, c.validate_rmse_K);
  int k = 0;
  for (const Candidate& c : rd.candidates) {
    if (!c.not_applicable.empty()) continue;
    const double wbar = 380.0 * c.validate_rmse_K / std::max(mx, 1e-9);
    h += fmt::format(
        "<text x='200' y='{}' text-anchor='end'>{}</text><rect x='205' y='{}' width='{:.1f}' "
        "height='12' fill='{}'/><text x='{:.1f}' y='{}'>{:.3f}</text>",
        14 + 16 * k, Html(c.label), 4 + 16 * k, wbar, c.eligible ? "#1f77b4" : "#aaa", 210 + wbar,
        14 + 16 * k, c.validate_rmse_K);
    ++k;
  }
  const double wb = 380.0 * rd.base_validate_rmse_K / std::max(mx, 1e-9);
  h += fmt::format(
      "<line x1='{:.1f}' x2='{:.1f}' y1='0' y2='{}' stroke='#d62728' stroke-dasharray='4 3'/>",
      205 + wb, 205 + wb, 16 * k + 4);
  return h +
         "</svg><p>Blue: eligible (significant, information criterion and validation gain met); "
         "dashed "
         "red: the input model.</p>";
}

}  // namespace

std::string ReportHtml(const Result& r, const std::string& model, const std::string& train,
                       const std::string& validate, const ReportContext& context) {
  std::string h =
      "<!DOCTYPE html><html><head><meta charset='utf-8'><title>pumptherm discrepancy</title>"
      "<style>body{font-family:sans-serif;max-width:1100px;margin:1em auto;padding:0 "
      "1em}table{border-collapse:"
      "collapse;width:100%}td,th{border:1px solid #ccc;padding:2px "
      "6px;text-align:right;white-space:nowrap}"
      "td:first-child{text-align:left}th{white-space:normal}td.why{white-space:normal;text-align:"
      "left;min-width:12em}td.val{white-space:normal;text-align:left;min-width:12em}svg{display:"
      "block;margin:4px 0}.row{display:flex;gap:4px}.row svg{flex:1;min-width:0}"
      "pre.diff{background:#f7f7f7;padding:6px;overflow-x:auto}.add{color:#1a7f37}.del{color:#"
      "c62828}"
      ".ctx{color:#555}.gap{color:#999}.crit{font-size:90%;color:#333}</style></head><body>";
  h += fmt::format(
      "<h1>Model discrepancy: {}</h1><p>Train: {}<br>Validate: {}<br>Files: <a href='model.toml'>"
      "model.toml</a> (the model with the effects added), <a "
      "href='report.json'>report.json</a></p>",
      Html(model), Html(train), Html(validate));
  h += fmt::format("<h2>Verdict: {}</h2>", Html(r.verdict));
  if (!r.effects.empty()) {
    h += "<ol>";
    for (const AddedEffect& e : r.effects)
      h += fmt::format("<li><b>{}</b>{}: {} = {}; {}</li>", Html(e.effect.name),
                       e.effect.node.empty() ? "" : " (" + Html(e.effect.node) + ")",
                       Html(e.parameters[0].name), Html(ValueWithInterval(e.parameters[0])),
                       Html(e.reading));
    h += "</ol>";
  }
  if (!context.input_model_toml.empty())
    h += "<h2>The model edit (model.toml against the input model)</h2>" +
         ModelEditHtml(context.input_model_toml, r.model_toml);
  h +=
      "<h2>Gap (simulated minus measured)</h2><table><tr><th>node</th><th>train RMSE before, K</th>"
      "<th>after</th><th>validate RMSE before, K</th><th>after</th><th>validate max before, K</th>"
      "<th>after</th></tr>";
  for (std::size_t i = 0; i < r.validate_before.size(); ++i)
    h += fmt::format(
        "<tr><td>{}</td><td>{:.3f}</td><td>{:.3f}</td><td>{:.3f}</td><td>{:.3f}</td><td>"
        "{:.3f}</td><td>{:.3f}</td></tr>",
        Html(r.validate_before[i].node), r.train_before[i].rmse_K, r.train_after[i].rmse_K,
        r.validate_before[i].rmse_K, r.validate_after[i].rmse_K, r.validate_before[i].max_abs_K,
        r.validate_after[i].max_abs_K);
  h += "</table>" + CriterionHtml(context.options);
  for (std::size_t ri = 0; ri < r.rounds.size(); ++ri)
    h += RoundHtml(ri, r.rounds[ri], context.options);
  h += PlotsHtml(r.validate_plot, context.validate);
  if (!r.rounds.empty()) h += RankingHtml(r.rounds[0]);
  return h + "</body></html>\n";
}

void WriteReport(const std::string& dir, const Result& r, const std::string& model,
                 const std::string& train, const std::string& validate,
                 const ReportContext& context) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) throw std::system_error(ec, "creating " + dir);
  auto write = [&](const std::string& name, const std::string& text) {
    const std::string path = dir + "/" + name;
    std::ofstream f(path, std::ios::binary);
    f << text;
    f.close();
    if (!f)
      throw std::system_error(errno ? errno : EIO, std::generic_category(), "writing " + path);
  };
  write("report.json", ReportJson(r, model, train, validate));
  write("model.toml", r.model_toml);
  write("report.html", ReportHtml(r, model, train, validate, context));
}

}  // namespace pumptherm::tools::discrepancy
