#include "tools/discrepancy/report.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <system_error>

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
    if (c == '<') out += "&lt;";
    else if (c == '>') out += "&gt;";
    else if (c == '&') out += "&amp;";
    else out += c;
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
      "{{\"name\": {}, \"effect\": {}, \"node\": {}, \"tried\": true, \"score\": {{\"validate_rmse_K\": {}, "
      "\"train_rmse_K\": {}, \"delta_ic\": {}, \"rho\": {}, \"n_eff\": {}}}, \"significant\": {}, "
      "\"eligible\": {}, \"parameters\": {}, \"evaluations\": {}}}",
      Str(c.label), Str(c.effect), c.node.empty() ? "null" : Str(c.node), Num(c.validate_rmse_K),
      Num(c.train_rmse_K), Num(c.delta_ic), Num(c.rho), Num(c.n_eff), c.significant ? "true" : "false",
      c.eligible ? "true" : "false", Params(c.parameters), c.evaluations);
}

/// A line plot as inline SVG: x in hours, one polyline per series.
struct Line {
  std::string name, colour;
  const std::vector<double>* y;
  bool dashed = false;
};

std::string Svg(const std::string& title, const std::vector<double>& t_s, const std::vector<Line>& lines,
                const std::string& ylabel) {
  const double w = 640, h = 260, l = 60, r = 150, top = 24, b = 36;
  double ymin = 1e300, ymax = -1e300;
  for (const Line& ln : lines)
    for (double v : *ln.y) {
      ymin = std::min(ymin, v);
      ymax = std::max(ymax, v);
    }
  if (!(ymax > ymin)) {
    ymax = ymin + 1.0;
    ymin -= 1.0;
  }
  const double pad = 0.05 * (ymax - ymin);
  ymin -= pad;
  ymax += pad;
  const double t0 = t_s.front(), t1 = std::max(t_s.back(), t0 + 1.0);
  auto X = [&](double t) { return l + (w - l - r) * (t - t0) / (t1 - t0); };
  auto Y = [&](double v) { return top + (h - top - b) * (ymax - v) / (ymax - ymin); };
  std::string s = fmt::format(
      "<svg xmlns='http://www.w3.org/2000/svg' width='{}' height='{}' font-family='sans-serif' "
      "font-size='11'><rect width='100%' height='100%' fill='white'/>"
      "<text x='{}' y='15' font-size='13'>{}</text>",
      w, h, l, Html(title));
  s += fmt::format("<rect x='{}' y='{}' width='{}' height='{}' fill='none' stroke='#888'/>", l, top,
                   w - l - r, h - top - b);
  for (int i = 0; i <= 4; ++i) {
    const double v = ymin + (ymax - ymin) * i / 4.0;
    s += fmt::format("<text x='{}' y='{:.1f}' text-anchor='end'>{:.3g}</text>", l - 4, Y(v) + 4, v);
    const double t = t0 + (t1 - t0) * i / 4.0;
    s += fmt::format("<text x='{:.1f}' y='{}' text-anchor='middle'>{:.3g}</text>", X(t), h - b + 14,
                     t / 3600.0);
  }
  s += fmt::format("<text x='{}' y='{}' text-anchor='middle'>time, h</text>", l + (w - l - r) / 2, h - 6);
  s += fmt::format("<text x='12' y='{}' transform='rotate(-90 12 {})' text-anchor='middle'>{}</text>",
                   top + (h - top - b) / 2, top + (h - top - b) / 2, Html(ylabel));
  int k = 0;
  for (const Line& ln : lines) {
    std::string pts;
    const std::size_t n = std::min(t_s.size(), ln.y->size());
    const std::size_t stride = std::max<std::size_t>(1, n / 800);
    for (std::size_t j = 0; j < n; j += stride) pts += fmt::format("{:.1f},{:.1f} ", X(t_s[j]), Y((*ln.y)[j]));
    s += fmt::format("<polyline fill='none' stroke='{}' stroke-width='1.2'{} points='{}'/>", ln.colour,
                     ln.dashed ? " stroke-dasharray='4 3'" : "", pts);
    s += fmt::format("<line x1='{}' x2='{}' y1='{}' y2='{}' stroke='{}'/><text x='{}' y='{}'>{}</text>",
                     w - r + 8, w - r + 28, top + 10 + 14 * k, top + 10 + 14 * k, ln.colour, w - r + 32,
                     top + 14 + 14 * k, Html(ln.name));
    ++k;
  }
  return s + "</svg>";
}

}  // namespace

std::string ReportJson(const Result& r, const std::string& model, const std::string& train,
                       const std::string& validate) {
  std::string j = "{\n";
  j += fmt::format("  \"model\": {},\n  \"train\": {},\n  \"validate\": {},\n", Str(model), Str(train),
                   Str(validate));
  j += fmt::format("  \"verdict\": {},\n", Str(r.verdict));
  j += fmt::format("  \"effect\": {},\n", Str(r.effects.empty() ? "none" : r.effects.front().effect.name));
  j += "  \"effects\": [";
  for (std::size_t i = 0; i < r.effects.size(); ++i) {
    const AddedEffect& e = r.effects[i];
    j += fmt::format("{}\n    {{\"name\": {}, \"node\": {}, \"parameters\": {}, \"reading\": {}}}",
                     i ? "," : "", Str(e.effect.name), e.effect.node.empty() ? "null" : Str(e.effect.node),
                     Params(e.parameters), Str(e.reading));
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
    j += fmt::format("{}\n    {{\"verdict\": {}, \"base_train_rmse_K\": {}, \"base_validate_rmse_K\": {}, "
                     "\"candidates\": [",
                     i ? "," : "", Str(rd.verdict), Num(rd.base_train_rmse_K), Num(rd.base_validate_rmse_K));
    for (std::size_t c = 0; c < rd.candidates.size(); ++c)
      j += (c ? ",\n      " : "\n      ") + CandidateJson(rd.candidates[c]);
    j += "]}";
  }
  j += "\n  ],\n";
  j += fmt::format(
      "  \"gap\": {{\n    \"train\": {{\"before\": {}, \"after\": {}}},\n    \"validate\": {{\"before\": {}, "
      "\"after\": {}}}\n  }},\n",
      Gap(r.train_before), Gap(r.train_after), Gap(r.validate_before), Gap(r.validate_after));
  j += fmt::format("  \"simulation\": {}, \"averaging_cost_K\": {{\"train\": {}, \"validate\": {}}},\n",
                   Str(r.simulation), Num(r.averaging_cost_train_K), Num(r.averaging_cost_validate_K));
  j += fmt::format("  \"run_time_s\": {}\n}}\n", Num(r.seconds));
  return j;
}

std::string ReportHtml(const Result& r, const std::string& model, const std::string& train,
                       const std::string& validate) {
  std::string h =
      "<!DOCTYPE html><html><head><meta charset='utf-8'><title>pumptherm discrepancy</title>"
      "<style>body{font-family:sans-serif;max-width:980px;margin:1em auto}table{border-collapse:"
      "collapse}td,th{border:1px solid #ccc;padding:2px 6px;text-align:right}td:first-child{text-align:"
      "left}</style></head><body>";
  h += fmt::format("<h1>Model discrepancy: {}</h1><p>Train: {}<br>Validate: {}</p>", Html(model),
                   Html(train), Html(validate));
  h += fmt::format("<h2>Verdict: {}</h2>", Html(r.verdict));
  if (!r.effects.empty()) {
    h += "<ol>";
    for (const AddedEffect& e : r.effects)
      h += fmt::format("<li><b>{}</b>{}: {} = {:.4g} (95 % {:.4g} to {:.4g}); {}</li>", Html(e.effect.name),
                       e.effect.node.empty() ? "" : " (" + Html(e.effect.node) + ")", Html(e.parameters[0].name),
                       e.parameters[0].value, e.parameters[0].low95, e.parameters[0].high95, Html(e.reading));
    h += "</ol>";
  }
  for (const Round& rd : r.rounds)
    if (rd.verdict == "ambiguous") {
      h += "<p>Cannot tell apart: ";
      for (const auto& t : rd.tied) h += Html(t) + " ";
      h += "<br>Experiment that would separate them: " + Html(rd.experiment) + "</p>";
    }
  h += "<h2>Gap (simulated minus measured)</h2><table><tr><th>node</th><th>train RMSE before, K</th>"
       "<th>after</th><th>validate RMSE before, K</th><th>after</th><th>validate max before, K</th>"
       "<th>after</th></tr>";
  for (std::size_t i = 0; i < r.validate_before.size(); ++i)
    h += fmt::format("<tr><td>{}</td><td>{:.3f}</td><td>{:.3f}</td><td>{:.3f}</td><td>{:.3f}</td><td>"
                     "{:.3f}</td><td>{:.3f}</td></tr>",
                     Html(r.validate_before[i].node), r.train_before[i].rmse_K, r.train_after[i].rmse_K,
                     r.validate_before[i].rmse_K, r.validate_after[i].rmse_K, r.validate_before[i].max_abs_K,
                     r.validate_after[i].max_abs_K);
  h += "</table>";
  for (std::size_t ri = 0; ri < r.rounds.size(); ++ri) {
    const Round& rd = r.rounds[ri];
    h += fmt::format("<h2>Round {}: {} (current model: train {:.3f} K, validate {:.3f} K)</h2>", ri + 1,
                     Html(rd.verdict), rd.base_train_rmse_K, rd.base_validate_rmse_K);
    h += "<table><tr><th>candidate</th><th>validate RMSE, K</th><th>train RMSE, K</th><th>dIC</th>"
         "<th>rho</th><th>n_eff</th><th>parameter</th><th>95 % interval</th><th>eligible</th></tr>";
    for (const Candidate& c : rd.candidates) {
      if (!c.not_applicable.empty()) {
        h += fmt::format("<tr><td>{}</td><td colspan='8' style='text-align:left'>not tried: {}</td></tr>",
                         Html(c.label), Html(c.not_applicable));
        continue;
      }
      const FittedParameter& p = c.parameters[0];
      h += fmt::format("<tr><td>{}</td><td>{:.3f}</td><td>{:.3f}</td><td>{:.1f}</td><td>{:.3f}</td><td>{:.0f}"
                       "</td><td>{:.4g}</td><td>{:.4g} to {:.4g}</td><td>{}</td></tr>",
                       Html(c.label), c.validate_rmse_K, c.train_rmse_K, c.delta_ic, c.rho, c.n_eff, p.value,
                       p.low95, p.high95, c.eligible ? "yes" : "no");
    }
    h += "</table>";
  }
  const PlotSeries& v = r.validate_plot;
  h += "<h2>Validation data: measured against simulated</h2>";
  for (std::size_t i = 0; i < v.nodes.size(); ++i) {
    h += Svg(v.nodes[i], v.time_s,
             {{"measured", "#000", &v.measured[i]},
              {"before", "#d62728", &v.before[i], true},
              {"after", "#1f77b4", &v.after[i]}},
             "degC");
    std::vector<double> rb(v.time_s.size()), ra(v.time_s.size());
    for (std::size_t j = 0; j < v.time_s.size(); ++j) {
      rb[j] = v.before[i][j] - v.measured[i][j];
      ra[j] = v.after[i][j] - v.measured[i][j];
    }
    h += Svg(v.nodes[i] + ": residual (simulated - measured)", v.time_s,
             {{"before", "#d62728", &rb, true}, {"after", "#1f77b4", &ra}}, "K");
  }
  if (!r.rounds.empty()) {
    h += "<h2>Candidate ranking, round 1 (validation RMSE, K)</h2><svg xmlns='http://www.w3.org/2000/svg' "
         "width='640' font-family='sans-serif' font-size='11' height='" +
         std::to_string(20 + 16 * r.rounds[0].candidates.size()) + "'>";
    double mx = r.rounds[0].base_validate_rmse_K;
    for (const Candidate& c : r.rounds[0].candidates) mx = std::max(mx, c.validate_rmse_K);
    int k = 0;
    for (const Candidate& c : r.rounds[0].candidates) {
      if (!c.not_applicable.empty()) continue;
      const double wbar = 380.0 * c.validate_rmse_K / std::max(mx, 1e-9);
      h += fmt::format("<text x='200' y='{}' text-anchor='end'>{}</text><rect x='205' y='{}' width='{:.1f}' "
                       "height='12' fill='{}'/><text x='{:.1f}' y='{}'>{:.3f}</text>",
                       14 + 16 * k, Html(c.label), 4 + 16 * k, wbar, c.eligible ? "#1f77b4" : "#aaa",
                       210 + wbar, 14 + 16 * k, c.validate_rmse_K);
      ++k;
    }
    const double wb = 380.0 * r.rounds[0].base_validate_rmse_K / std::max(mx, 1e-9);
    h += fmt::format("<line x1='{:.1f}' x2='{:.1f}' y1='0' y2='{}' stroke='#d62728' stroke-dasharray='4 3'/>",
                     205 + wb, 205 + wb, 16 * k + 4);
    h += "</svg><p>Blue: eligible (significant, information criterion and validation gain met); dashed "
         "red: the input model.</p>";
  }
  return h + "</body></html>\n";
}

void WriteReport(const std::string& dir, const Result& r, const std::string& model,
                 const std::string& train, const std::string& validate) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) throw std::system_error(ec, "creating " + dir);
  auto write = [&](const std::string& name, const std::string& text) {
    const std::string path = dir + "/" + name;
    std::ofstream f(path, std::ios::binary);
    f << text;
    f.close();
    if (!f) throw std::system_error(errno ? errno : EIO, std::generic_category(), "writing " + path);
  };
  write("report.json", ReportJson(r, model, train, validate));
  write("model.toml", r.model_toml);
  write("report.html", ReportHtml(r, model, train, validate));
}

}  // namespace pumptherm::tools::discrepancy
