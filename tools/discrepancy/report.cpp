#include "tools/discrepancy/report.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <array>
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

/// report.json's "model_right_now" object (defined with the residual tests below).
std::string RightNowJson(const Result& r, const ReportContext& context);

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
  /// The x range drawn; NaN: the ticks' ends.
  double x_lo = std::nan(""), x_hi = std::nan("");
  double Lo() const { return std::isfinite(x_lo) ? x_lo : xt.front(); }
  double Hi() const { return std::isfinite(x_hi) ? x_hi : xt.back(); }
  double X(double x) const { return f.l + (f.w - f.l - f.r) * (x - Lo()) / (Hi() - Lo()); }
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
    if (x >= a.Lo() - 1e-9 && x <= a.Hi() + 1e-9)
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
  // The legend right of the plot, wide enough for "before: fit -31.3 %, RMSE 9.97 K" (about 7
  // units a character), the same for every time plot so that their time axes line up.
  std::size_t longest = 0;
  for (const Line& ln : lines) longest = std::max(longest, ln.name.size());
  a.f.r = std::max(270.0, 40.0 + 7.0 * static_cast<double>(longest));
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

/// Correlation against lag as stems, with the test's band +/- `band` (dashed) and a zero line.
std::string CorrSvg(const std::string& title, const std::vector<double>& lag,
                    const std::vector<double>& c, double band, const std::string& xlabel) {
  Axes a;
  a.f = Frame{320, 220, 46, 10, 24, 38};
  a.yt = NiceTicks(-1.0, 1.0, 4);
  a.xt = NiceTicks(lag.front(), lag.back(), 4);
  a.x_lo = lag.front();  // the axis spans the lags computed, no further
  a.x_hi = lag.back();
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

/// The validation inputs averaged over each plot grid step (t_{k-1}, t_k]: speed, the current
/// amplitude as rms of sqrt(id^2 + iq^2) (so its square keeps the copper loss), the ambient and
/// the coolant temperatures.
void InputsOnGrid(const Data& d, const std::vector<double>& grid_s, std::vector<double>& speed_rpm,
                  std::vector<double>& current_A, std::vector<double>& ambient_degC,
                  std::vector<double>& coolant_degC) {
  std::array<std::vector<double>*, 4> out{&speed_rpm, &current_A, &ambient_degC, &coolant_degC};
  for (auto* v : out) v->assign(grid_s.size(), std::nan(""));
  std::size_t j = 0;
  for (std::size_t k = 0; k < grid_s.size(); ++k) {
    double n = 0, sp = 0, i2 = 0, amb = 0, cool = 0;
    for (; j < d.size() && d.time_s[j] <= grid_s[k]; ++j) {
      sp += d.speed_rpm[j];
      i2 += d.id_A[j] * d.id_A[j] + d.iq_A[j] * d.iq_A[j];
      amb += d.ambient_degC[j];
      cool += d.coolant_degC[j];
      ++n;
    }
    if (n > 0) {
      speed_rpm[k] = sp / n;
      current_A[k] = std::sqrt(i2 / n);
      ambient_degC[k] = amb / n;
      coolant_degC[k] = cool / n;
    } else if (k > 0) {
      for (auto* v : out) (*v)[k] = (*v)[k - 1];
    }
  }
  for (std::size_t k = grid_s.size(); k-- > 1;)  // grid points before the first sample
    if (std::isnan(speed_rpm[k - 1]))
      for (auto* v : out) (*v)[k - 1] = (*v)[k];
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

/// The parameter's physical range (the effect vocabulary's bounds), or nullptr when not known.
const estimators::EffectParameterSpec* SpecOf(const FittedParameter& p) {
  for (const estimators::EffectSpec& e : estimators::EffectVocabulary())
    for (const estimators::EffectParameterSpec& ps : e.parameters)
      if (p.name == ps.name || p.name.rfind(ps.name + "__", 0) == 0) return &ps;
  return nullptr;
}

/// Whether the data determine the parameter: its 95 % interval is known and narrower than its
/// whole physical range (wider, the data say nothing about it: it is unidentifiable).
bool Identifiable(const FittedParameter& p) {
  if (!std::isfinite(p.low95) || !std::isfinite(p.high95)) return false;
  const estimators::EffectParameterSpec* ps = SpecOf(p);
  return ps == nullptr || p.high95 - p.low95 < ps->upper - ps->lower;
}

/// "value (95 % low to high) unit" with the decimals that show the interval's width to three
/// significant figures (four significant figures of the value when the width is 0 or unknown);
/// the interval clipped to the parameter's physical range (said so), or "unidentifiable" when
/// it is wider than that range.
std::string ValueWithInterval(const FittedParameter& p) {
  const estimators::EffectParameterSpec* ps = SpecOf(p);
  double lo = p.low95, hi = p.high95;
  const bool identifiable = Identifiable(p);
  bool clipped = false;
  if (identifiable && ps != nullptr) {
    clipped = lo < ps->lower || hi > ps->upper;
    lo = std::max(lo, ps->lower);
    hi = std::min(hi, ps->upper);
  }
  const double width = std::abs(hi - lo);
  const double scale =
      identifiable && width > 0 && std::isfinite(width) ? width : std::abs(p.value);
  const int dec =
      std::clamp(scale > 0 ? 2 - static_cast<int>(std::floor(std::log10(scale))) : 3, 0, 12);
  const std::string unit = UnitOf(p.name);
  const std::string u = unit.rfind("1 ", 0) == 0 ? "" : " " + unit;
  if (!identifiable)
    return fmt::format("{:.4g}{} (unidentifiable: the data do not determine it)", p.value, u);
  return fmt::format("{:.{}f} (95 % {:.{}f} to {:.{}f}{}){}", p.value, dec, lo, dec, hi, dec,
                     clipped ? ", clipped to the physical range" : "", u);
}

/// `value` and `threshold` with `unit`, to as many decimals (from `decimals`) as it takes for the
/// printed value to differ from the printed threshold, so that "9.96 % < 10 %" never reads
/// "10.0 % < 10 %".
std::string Against(double value, double threshold, int decimals) {
  int d = decimals;
  while (d < 6 && fmt::format("{:.{}f}", value, d) == fmt::format("{:.{}f}", threshold, d)) ++d;
  return fmt::format("{:.{}f}", value, d);
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
    why.push_back(
        fmt::format("dIC {} > -{}", Against(c.delta_ic, -o.ic_threshold, 1), o.ic_threshold));
  const double gain = 1.0 - c.validate_rmse_K / rd.base_validate_rmse_K;
  if (!(gain >= o.min_validation_gain))
    why.push_back(fmt::format("validation gain {} % < {:.0f} %",
                              Against(100 * gain, 100 * o.min_validation_gain, 1),
                              100 * o.min_validation_gain));
  if (const estimators::EffectSpec* spec = estimators::FindEffect(c.effect); spec != nullptr) {
    const auto& ps = spec->parameters.front();
    const double v = c.parameters[0].value, tol = 1e-6 * (ps.upper - ps.lower);
    if (v <= ps.lower + tol || v >= ps.upper - tol)
      why.push_back(fmt::format("at its physical bound ({})",
                                Num(v <= ps.lower + tol ? ps.lower : ps.upper)));
  }
  const bool tied = std::find(rd.tied.begin(), rd.tied.end(), c.label) != rd.tied.end();
  if (!why.empty()) {
    std::string out;
    for (const auto& w : why) out += (out.empty() ? "" : "; ") + w;
    if (tied)
      out += fmt::format(
          "; within the {:.0f} % margin of a best that is not clearly better than the current "
          "model: cannot tell apart",
          100 * o.margin);
    return out;
  }
  if (tied)
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
                       const std::string& validate, const ReportContext& context) {
  std::string j = "{\n";
  j += fmt::format("  \"model\": {},\n  \"train\": {},\n  \"validate\": {},\n", Str(model),
                   Str(train), Str(validate));
  j += "  \"model_right_now\": " + RightNowJson(r, context) + ",\n";
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
      "criterion dIC = n_eff ln(SSR/SSR<sub>current</sub>) + ln(n_eff) is at most -{1} (lower is "
      "better; BIC at the effective sample size n_eff = n (1 - rho)/(1 + rho)); its 95 % interval "
      "excludes the neutral value (significant); and it cuts the current model's validation RMSE "
      "by at least {2:.0f} %. Values at a physical bound are flagged. The best eligible one is "
      "<i>named</i> unless a rival has a validation RMSE below {0:.2f} x its own and is eligible "
      "too, or the best is not {0:.2f} times better than the current model either; then the "
      "round is ambiguous. An ineligible rival cannot block a best that is clearly better than "
      "the current model (docs/discrepancy.md, How it decides).</p>",
      1.0 + o.margin, o.ic_threshold, 100 * o.min_validation_gain);
}

/// One residual test over every lag it plots (MATLAB's `resid` reading): a lag fails when its
/// correlation lies outside the band; the test passes when none does. The band holds the whole
/// test at 95 % (FamilyZ), not each lag: a right model then passes it 95 % of the time.
struct LagTest {
  std::string input;  ///< "" for the whiteness test (the autocorrelation), else the input
  double band = 0.0;
  double peak = 0.0, peak_lag_min = 0.0;  ///< the largest |correlation| and its lag
  double step_min = 0.0;                  ///< the lag grid's step
  std::vector<double> failing_lags_min;
  /// A band at or above 1: no correlation can fail it, so the test cannot tell (a residual and
  /// an input that move too slowly for the validation data's length).
  bool powerless() const { return band >= 1.0; }
  bool pass() const { return failing_lags_min.empty() && !powerless(); }
};

/// The residuals of one node against the inputs: correlations, bands and tests.
struct ResidualCheck {
  std::vector<double> lag_min;           ///< -M..M grid steps, min
  std::vector<double> ree;               ///< autocorrelation, lags -M..M
  std::vector<std::vector<double>> reu;  ///< per input, lags -M..M
  std::vector<LagTest> tests;            ///< whiteness, then one per input
};

/// The validation inputs on the plot grid, each with its name and unit.
struct InputStrip {
  std::string name, unit, colour;
  std::vector<double> values;
  /// Whether the residuals are tested against it: the speed and the current always; a boundary
  /// temperature only when it moves by more than 1 K (a constant one drives nothing, and its
  /// sensor's noise would only add lags failed by chance).
  bool tested = true;
};

/// The two-sided standard normal quantile whose tails hold `p`: erfc(z / sqrt 2) = p, by
/// bisection on the standard library's erfc (monotone; 60 halvings reach double precision).
double TwoSidedZ(double p) {
  double lo = 0.0, hi = 40.0;
  for (int i = 0; i < 60; ++i) {
    const double mid = 0.5 * (lo + hi);
    (std::erfc(mid / std::sqrt(2.0)) > p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

/// z of the band that a test over `lags` lags fails by chance 5 % of the time (Sidak 1967: each
/// lag at 1 - 0.95^(1/lags), conservative for correlated lags): 1.96 for one lag, 3.22 for 40,
/// 3.42 for 81. Each lag at 1.96 instead, 40 independent lags fail together 87 % of the time.
double FamilyZ(int lags) {
  return TwoSidedZ(1.0 - std::pow(0.95, 1.0 / static_cast<double>(std::max(lags, 1))));
}

/// Residual autocorrelation and cross-correlation with the inputs, as MATLAB's resid shows them.
/// Bands (z = FamilyZ of the test's lag count): +/- z/sqrt(N) for the autocorrelation (white
/// residuals) at lags 1..M; for the cross-correlation z sqrt(var), var = (1/N) sum_j r_ee(j)
/// r_uu(j) over the plotted lags:
/// Bartlett's variance of a sample cross-correlation (Bartlett 1978, An Introduction to
/// Stochastic Processes, 3rd ed., p. 352) with the true cross-correlation zero, 1/(N - k) taken
/// as 1/N (lags at most N/4). M = min(40, N/4) grid steps. Empty with fewer than 8 points.
ResidualCheck CheckResiduals(const std::vector<double>& t_s, const std::vector<double>& res,
                             const std::vector<InputStrip>& inputs) {
  ResidualCheck rc;
  const std::size_t n = res.size();
  if (n < 8) return rc;
  const int max_lag = static_cast<int>(std::min<std::size_t>(40, n / 4));
  const double step_min = (t_s.back() - t_s.front()) / static_cast<double>(n - 1) / 60.0;
  for (int k = -max_lag; k <= max_lag; ++k) rc.lag_min.push_back(k * step_min);
  rc.ree = CrossCorrelation(res, res, max_lag);
  const double sqrt_n = std::sqrt(static_cast<double>(n));
  auto test = [&](const std::string& input, const std::vector<double>& r, double band, int from) {
    LagTest t;
    t.input = input;
    t.band = band;
    t.step_min = step_min;
    for (int k = from; k < static_cast<int>(r.size()); ++k) {
      const double a = std::abs(r[static_cast<std::size_t>(k)]);
      if (a > t.peak) {
        t.peak = a;
        t.peak_lag_min = rc.lag_min[static_cast<std::size_t>(k)];
      }
      if (a > band) t.failing_lags_min.push_back(rc.lag_min[static_cast<std::size_t>(k)]);
    }
    rc.tests.push_back(t);
  };
  const double z_ee = FamilyZ(max_lag), z_eu = FamilyZ(2 * max_lag + 1);
  test("", rc.ree, z_ee / sqrt_n, max_lag + 1);  // lags 1..M
  for (const InputStrip& u : inputs) {
    const std::vector<double> ruu = CrossCorrelation(u.values, u.values, max_lag);
    double var = 0;
    for (int k = 0; k < 2 * max_lag + 1; ++k) var += rc.ree[k] * ruu[k];
    rc.reu.push_back(CrossCorrelation(res, u.values, max_lag));
    test(u.name, rc.reu.back(), z_eu * std::sqrt(std::max(var, 1.0)) / sqrt_n, 0);
  }
  return rc;
}

/// The failing lags in minutes, neighbours joined into ranges: "0.5 to 3.0, 5.0".
std::string FailingLagsText(const LagTest& t) {
  std::string lags;
  const std::vector<double>& f = t.failing_lags_min;
  const double step = t.step_min;
  for (std::size_t i = 0; i < f.size();) {
    std::size_t j = i;
    while (j + 1 < f.size() && std::abs(f[j + 1] - f[j] - step) < 1e-6 * (1 + step) && step > 0)
      ++j;
    lags += (lags.empty() ? "" : ", ") +
            (j > i ? fmt::format("{:.1f} to {:.1f}", f[i], f[j]) : fmt::format("{:.1f}", f[i]));
    i = j + 1;
  }
  return lags;
}

/// "FAILS at lags 0.5 to 3.0, 5.0 min (peak 0.72 at 1.0 min, band 0.55)", "passes (peak 0.31
/// at 2.0 min, band 0.55)".
std::string LagTestText(const LagTest& t) {
  if (t.powerless())
    return fmt::format(
        "cannot tell (peak {:.2f} at {:.1f} min, band {:.2f}: no correlation "
        "reaches it)",
        t.peak, t.peak_lag_min, t.band);
  if (t.pass())
    return fmt::format("passes (peak {:.2f} at {:.1f} min, band {:.2f})", t.peak, t.peak_lag_min,
                       t.band);
  return fmt::format("FAILS at lags {} min (peak {:.2f} at {:.1f} min, band {:.2f})",
                     FailingLagsText(t), t.peak, t.peak_lag_min, t.band);
}

/// MATLAB compare's fit: 100 (1 - |y - yhat| / |y - mean(y)|), %, grid points 1.. (point 0 is
/// the start, as in the gap table).
double FitPercent(const std::vector<double>& measured, const std::vector<double>& simulated) {
  double mean = 0.0;
  const std::size_t n = measured.size();
  if (n < 2) return std::nan("");
  for (std::size_t j = 1; j < n; ++j) mean += measured[j] / static_cast<double>(n - 1);
  double err = 0.0, spread = 0.0;
  for (std::size_t j = 1; j < n; ++j) {
    err += (measured[j] - simulated[j]) * (measured[j] - simulated[j]);
    spread += (measured[j] - mean) * (measured[j] - mean);
  }
  return spread > 0.0 ? 100.0 * (1.0 - std::sqrt(err / spread)) : std::nan("");
}

double Rmse(const std::vector<double>& measured, const std::vector<double>& simulated) {
  double ss = 0.0;
  for (std::size_t j = 1; j < measured.size(); ++j)
    ss += (measured[j] - simulated[j]) * (measured[j] - simulated[j]);
  return measured.size() > 1 ? std::sqrt(ss / static_cast<double>(measured.size() - 1))
                             : std::nan("");
}

/// What the report says about one node's model, before and after the effects.
struct NodeVerdict {
  std::string node;
  double fit_before = 0.0, fit_after = 0.0, rmse_before = 0.0, rmse_after = 0.0;
  ResidualCheck before, after;
};

std::vector<InputStrip> Inputs(const PlotSeries& v, const Data* data) {
  std::vector<InputStrip> out;
  if (data == nullptr || data->size() == 0 || v.time_s.empty()) return out;
  std::vector<double> speed, current, ambient, coolant;
  InputsOnGrid(*data, v.time_s, speed, current, ambient, coolant);
  auto moves = [](const std::vector<double>& series) {
    const auto [lo, hi] = std::minmax_element(series.begin(), series.end());
    return lo != series.end() && *hi - *lo > 1.0;
  };
  out.push_back({"speed", "r/min", "#2ca02c", speed});
  out.push_back({"current", "A", "#9467bd", current});
  out.push_back({"ambient", "degC", "#8c564b", ambient, moves(ambient)});
  bool own_coolant = false;
  for (std::size_t k = 0; k < data->size(); ++k)
    own_coolant = own_coolant || data->coolant_degC[k] != data->ambient_degC[k];
  if (own_coolant) out.push_back({"coolant", "degC", "#17becf", coolant, moves(coolant)});
  return out;
}

std::vector<NodeVerdict> Verdicts(const PlotSeries& v, const std::vector<InputStrip>& inputs) {
  std::vector<NodeVerdict> out;
  for (std::size_t i = 0; i < v.nodes.size(); ++i) {
    NodeVerdict nv;
    nv.node = v.nodes[i];
    nv.fit_before = FitPercent(v.measured[i], v.before[i]);
    nv.fit_after = FitPercent(v.measured[i], v.after[i]);
    nv.rmse_before = Rmse(v.measured[i], v.before[i]);
    nv.rmse_after = Rmse(v.measured[i], v.after[i]);
    std::vector<double> rb(v.time_s.size()), ra(v.time_s.size());
    for (std::size_t j = 0; j < v.time_s.size(); ++j) {
      rb[j] = v.before[i][j] - v.measured[i][j];
      ra[j] = v.after[i][j] - v.measured[i][j];
    }
    nv.before = CheckResiduals(v.time_s, rb, inputs);
    nv.after = CheckResiduals(v.time_s, ra, inputs);
    out.push_back(std::move(nv));
  }
  return out;
}

/// The validation inputs, those the residuals are tested against, and each node's verdict.
struct Analysis {
  std::vector<InputStrip> inputs, tested;
  std::vector<NodeVerdict> verdicts;
};

Analysis Analyse(const Result& r, const ReportContext& context) {
  Analysis a;
  a.inputs = Inputs(r.validate_plot, context.validate);
  for (const InputStrip& u : a.inputs)
    if (u.tested) a.tested.push_back(u);
  a.verdicts = Verdicts(r.validate_plot, a.tested);
  return a;
}

std::string Join(const std::vector<std::string>& parts, const std::string& sep) {
  std::string out;
  for (const std::string& p : parts) out += (out.empty() ? "" : sep) + p;
  return out;
}

/// "after adding frame_ambient_resistance, sensor_lag(frame)" or "with no effect added".
std::string EffectsText(const Result& r) {
  std::vector<std::string> names;
  for (const AddedEffect& e : r.effects)
    names.push_back(e.effect.name + (e.effect.node.empty() ? "" : "(" + e.effect.node + ")"));
  return names.empty() ? "with no effect added" : "after adding " + Join(names, ", ");
}

/// "frame: fit 93.5 %, RMSE 0.493 K; winding: ..." (after the effects), nodes with tests only.
std::string FitsText(const std::vector<NodeVerdict>& verdicts) {
  std::vector<std::string> parts;
  for (const NodeVerdict& v : verdicts)
    if (!v.after.tests.empty())
      parts.push_back(
          std::isfinite(v.fit_after)
              ? fmt::format("{}: fit {:.1f} %, RMSE {:.3f} K", v.node, v.fit_after, v.rmse_after)
              : fmt::format("{}: RMSE {:.3f} K", v.node, v.rmse_after));
  return Join(parts, "; ");
}

/// "frame's residual follows the current (fails at lags -0.2 to 3.8 min; peak 0.73, band 0.54)
/// and is not white (...)"; "" when every test of the node passes.
std::string NodeFailText(const NodeVerdict& v) {
  std::vector<std::string> clauses;
  auto detail = [](const LagTest& t) {
    return fmt::format("(fails at lags {} min; peak {:.2f}, band {:.2f})", FailingLagsText(t),
                       t.peak, t.band);
  };
  for (const LagTest& t : v.after.tests)
    if (!t.failing_lags_min.empty() && !t.input.empty())
      clauses.push_back("follows the " + t.input + " " + detail(t));
  for (const LagTest& t : v.after.tests)
    if (!t.failing_lags_min.empty() && t.input.empty())
      clauses.push_back("is not white " + detail(t));
  for (const LagTest& t : v.after.tests)
    if (t.powerless())
      clauses.push_back(
          fmt::format("cannot be tested against the {} (band {:.2f}: more "
                      "validation data needed)",
                      t.input.empty() ? "lags" : t.input, t.band));
  return clauses.empty() ? "" : v.node + "'s residual " + Join(clauses, " and ");
}

}  // namespace

namespace {

/// The answer from an analysis already made (the page and report.json make theirs once).
ModelRightNow RightNow(const Result& r, const Analysis& a) {
  std::vector<std::string> failing;
  bool tested = false, driven = false, failed = false;
  for (const NodeVerdict& v : a.verdicts) {
    tested = tested || !v.after.tests.empty();
    for (const LagTest& t : v.after.tests) {
      driven = driven || (!t.failing_lags_min.empty() && !t.input.empty());
      failed = failed || !t.failing_lags_min.empty();
    }
    const std::string f = NodeFailText(v);
    if (!f.empty()) failing.push_back(f);
  }
  if (!tested)
    return {"untested",
            "Model right now: untested: no measured node has the 8 validation points the "
            "residual tests need"};
  std::vector<std::string> inputs;
  for (const InputStrip& u : a.tested) inputs.push_back(u.name);
  const std::string not_tested = "cross-correlation not tested: no validation inputs given";
  if (failing.empty())
    return {"yes", fmt::format("Model right now: yes: every tested node passes whiteness {} on the "
                               "validation data {}; {}",
                               inputs.empty() ? "(" + not_tested + ")"
                                              : "and cross-correlation with " + Join(inputs, ", "),
                               EffectsText(r), FitsText(a.verdicts))};
  std::string meaning = "an input still drives the residual: an effect the model misses";
  if (!failed)
    meaning =
        "the tests cannot decide on this validation data: record a longer one, or one whose "
        "inputs change more often";
  else if (!driven)
    meaning = inputs.empty() ? not_tested
                             : "no input drives it: a slow error the inputs do not explain (the "
                               "plant's own disturbances, or an effect outside the vocabulary); "
                               "weigh it with the fit and RMSE";
  return {"not yet", fmt::format("Model right now: not yet: {} {}; {}; {}", Join(failing, "; "),
                                 EffectsText(r), FitsText(a.verdicts), meaning)};
}

}  // namespace

ModelRightNow CheckModelRightNow(const Result& r, const ReportContext& context) {
  return RightNow(r, Analyse(r, context));
}

namespace {

std::string LagTestJson(const LagTest& t) {
  std::string lags;
  for (double l : t.failing_lags_min) lags += (lags.empty() ? "" : ", ") + Num(l);
  return fmt::format(
      "{{\"test\": {}, \"pass\": {}, \"failing_lags_min\": [{}], \"peak\": {}, "
      "\"peak_lag_min\": {}, \"band\": {}}}",
      Str(t.input.empty() ? "whiteness" : "x " + t.input), t.pass() ? "true" : "false", lags,
      Num(t.peak), Num(t.peak_lag_min), Num(t.band));
}

std::string RightNowJson(const Result& r, const ReportContext& context) {
  const Analysis a = Analyse(r, context);
  const ModelRightNow m = RightNow(r, a);
  std::string j =
      fmt::format("{{\"answer\": {}, \"line\": {}, \"nodes\": [", Str(m.answer), Str(m.line));
  for (std::size_t i = 0; i < a.verdicts.size(); ++i) {
    const NodeVerdict& v = a.verdicts[i];
    std::string tests;
    for (const LagTest& t : v.after.tests) tests += (tests.empty() ? "" : ", ") + LagTestJson(t);
    j += fmt::format(
        "{}\n    {{\"node\": {}, \"fit_percent\": {}, \"rmse_K\": {}, \"tests\": [{}]}}",
        i ? "," : "", Str(v.node), Num(v.fit_after), Num(v.rmse_after), tests);
  }
  return j + (a.verdicts.empty() ? "]}" : "\n  ]}");
}

/// "Is the model right now?": per node the fit and every residual test, before and after.
std::string TestsHtml(const std::vector<NodeVerdict>& verdicts) {
  std::string h =
      "<h2>Is the model right now? Residual tests on the validation data</h2>"
      "<p class='crit'>As MATLAB's <i>compare</i> and <i>resid</i> read them: the fit is 100 (1 - "
      "|measured - simulated| / |measured - its mean|) %; the <b>whiteness</b> test asks whether "
      "the residuals (simulated - measured) are uncorrelated with themselves at lags 1 to M, the "
      "<b>cross-correlation</b> tests whether they are uncorrelated with each input at lags -M "
      "to M (an input leads at positive lags). A lag fails when its correlation lies outside the "
      "band; a test passes when no lag fails. The band holds each test, over all its lags, at 95 "
      "%: a right model passes it 95 % of the time. A residual the inputs still drive means an "
      "effect the model misses (docs/discrepancy.md, \"Residual tests\").</p>"
      "<table><tr><th>node</th><th>test</th><th>before</th><th>after</th></tr>";
  for (const NodeVerdict& v : verdicts) {
    const std::size_t tests = v.after.tests.size();
    h += fmt::format(
        "<tr><td rowspan='{}'>{}</td><td>fit, RMSE</td><td class='why'>{:.1f} %, {:.3f} K</td>"
        "<td class='why'>{:.1f} %, {:.3f} K</td></tr>",
        tests + 1, Html(v.node), v.fit_before, v.rmse_before, v.fit_after, v.rmse_after);
    for (std::size_t k = 0; k < tests; ++k) {
      const LagTest& a = v.after.tests[k];
      const LagTest& b = v.before.tests[k];
      auto cell = [](const LagTest& t) {
        return fmt::format("<td class='why {}'>{}</td>", t.pass() ? "pass" : "fail",
                           Html(LagTestText(t)));
      };
      h += fmt::format("<tr><td>{}</td>{}{}</tr>",
                       a.input.empty() ? "whiteness" : "x " + Html(a.input), cell(b), cell(a));
    }
  }
  return h + "</table>";
}

/// The correlation plots of one node's residuals (its autocorrelation, then one per input).
std::string CorrelationRow(const std::string& title, const ResidualCheck& rc,
                           const std::vector<InputStrip>& inputs) {
  if (rc.tests.empty()) return "";
  const std::size_t m = (rc.lag_min.size() - 1) / 2;
  const std::vector<double> pos_lag(rc.lag_min.begin() + static_cast<long>(m), rc.lag_min.end()),
      pos_ree(rc.ree.begin() + static_cast<long>(m), rc.ree.end());
  std::string h = "<div class='row'>" + CorrSvg(title + ": residual autocorrelation", pos_lag,
                                                pos_ree, rc.tests[0].band, "lag, min");
  for (std::size_t k = 0; k < inputs.size() && k < rc.reu.size(); ++k)
    h += CorrSvg(title + ": residual x " + inputs[k].name, rc.lag_min, rc.reu[k],
                 rc.tests[k + 1].band, "lag, min (input leads at +)");
  return h + "</div>";
}

std::string PlotsHtml(const PlotSeries& v, const std::vector<InputStrip>& inputs,
                      const std::vector<InputStrip>& tested,
                      const std::vector<NodeVerdict>& verdicts) {
  std::string h = "<h2>Validation data: measured against simulated</h2>";
  for (std::size_t i = 0; i < v.nodes.size(); ++i) {
    const NodeVerdict& nv = verdicts[i];
    h += "<h3>" + Html(v.nodes[i]) + "</h3>";
    h += Svg(v.nodes[i] + ": temperature", v.time_s,
             {{fmt::format("before: fit {:.1f} %, RMSE {:.2f} K", nv.fit_before, nv.rmse_before),
               "#d62728", &v.before[i], true, 1.4},
              {fmt::format("after: fit {:.1f} %, RMSE {:.2f} K", nv.fit_after, nv.rmse_after),
               "#1f77b4", &v.after[i], false, 2.4},
              {"measured", "#000", &v.measured[i], false, 1.0}},
             "degC");
    for (const InputStrip& u : inputs)
      h += Svg("input: " + u.name, v.time_s, {{u.name, u.colour, &u.values}}, u.unit, false, 140);
    std::vector<double> rb(v.time_s.size()), ra(v.time_s.size());
    for (std::size_t j = 0; j < v.time_s.size(); ++j) {
      rb[j] = v.before[i][j] - v.measured[i][j];
      ra[j] = v.after[i][j] - v.measured[i][j];
    }
    h += Svg(v.nodes[i] + ": residual (simulated - measured)", v.time_s,
             {{"before", "#d62728", &rb, true, 1.4}, {"after", "#1f77b4", &ra, false, 1.4}}, "K",
             true);
    h += CorrelationRow(v.nodes[i] + " before", nv.before, tested);
    h += CorrelationRow(v.nodes[i] + " after", nv.after, tested);
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
      ".ctx{color:#555}.gap{color:#999}.crit{font-size:90%;color:#333}td.pass{color:#1a7f37}"
      "td.fail{color:#c62828}p.now{font-size:115%;padding:6px;border-left:6px solid}p.now.pass{"
      "border-color:#1a7f37}p.now.fail{border-color:#c62828}</style></head><body>";
  const Analysis a = Analyse(r, context);
  const ModelRightNow right_now = RightNow(r, a);
  h += fmt::format("<p class='now {}'><b>{}</b></p>", right_now.answer == "yes" ? "pass" : "fail",
                   Html(right_now.line));
  h += fmt::format(
      "<h1>Model discrepancy: {}</h1><p>Train: {}<br>Validate: {}<br>Files: <a href='model.toml'>"
      "model.toml</a> (the model with the effects added), <a "
      "href='report.json'>report.json</a></p>",
      Html(model), Html(train), Html(validate));
  h += fmt::format("<h2>Which effects the model misses: {}</h2>", Html(r.verdict));
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
  h += "</table>" + TestsHtml(a.verdicts) + CriterionHtml(context.options);
  for (std::size_t ri = 0; ri < r.rounds.size(); ++ri)
    h += RoundHtml(ri, r.rounds[ri], context.options);
  h += PlotsHtml(r.validate_plot, a.inputs, a.tested, a.verdicts);
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
  write("report.json", ReportJson(r, model, train, validate, context));
  write("model.toml", r.model_toml);
  write("report.html", ReportHtml(r, model, train, validate, context));
}

}  // namespace pumptherm::tools::discrepancy
