#include "tools/discrepancy/workflow.hpp"

#include <ceres/ceres.h>
#include <fmt/core.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <chrono>
#include <cmath>
#include <functional>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <unordered_map>

#include "estimators/thermal_discretisation.hpp"
#include "estimators/thermal_model.hpp"

namespace pumptherm::tools::discrepancy {
namespace pe = pumptherm::estimators;
namespace {

/// A data set on the simulation grid. The simulation steps over `rows` (each row's inputs held
/// until the next row); the residuals are taken at the grid points, rows `at[j]`.
struct Grid {
  std::vector<double> t_s;            ///< grid points' times
  std::vector<std::size_t> at;        ///< grid point j is row at[j]
  std::vector<double> row_t_s;        ///< rows' times
  std::vector<pe::ThermalInputs> in;  ///< in[k] acts over [row_t_k, row_t_k+1)
  std::vector<char> rediscretise;     ///< row step k needs a new exp(A tau): fixed by the data
  bool averaged = false;              ///< rows are averages over grid steps, not the data's rows
  std::vector<std::string> nodes;
  std::vector<std::vector<double>> measured;  ///< [node][j]
};

/// Grid points: the data thinned to steps of at least min_grid_step_s and at most
/// max_grid_points points (indices into the data's rows).
std::vector<std::size_t> GridPoints(const Data& d, const Options& o) {
  const double span = d.time_s.back() - d.time_s.front();
  const double step = std::max(o.min_grid_step_s, span / std::max(1, o.max_grid_points - 1));
  std::vector<std::size_t> idx{0};
  for (std::size_t k = 1; k < d.size(); ++k)
    if (d.time_s[k] - d.time_s[idx.back()] >= step * (1.0 - 1e-9)) idx.push_back(k);
  return idx;
}

/// Inputs averaged over rows [a, b) by time: the currents as root mean squares (the copper loss,
/// i^2, is kept; the sign of iq is the step's mean sign), the rest as means.
pe::ThermalInputs AverageInputs(const Data& d, std::size_t a, std::size_t b) {
  const std::size_t n = d.size();
  double w = 0.0, sp = 0.0, id2 = 0.0, iq2 = 0.0, iq = 0.0, amb = 0.0, cool = 0.0;
  for (std::size_t k = a; k < b; ++k) {
    const double dt = k + 1 < n ? d.time_s[k + 1] - d.time_s[k] : 1.0;
    w += dt;
    sp += dt * d.speed_rpm[k];
    id2 += dt * d.id_A[k] * d.id_A[k];
    iq2 += dt * d.iq_A[k] * d.iq_A[k];
    iq += dt * d.iq_A[k];
    amb += dt * d.ambient_degC[k];
    cool += dt * d.coolant_degC[k];
  }
  pe::ThermalInputs in;
  in.speed_rpm = sp / w;
  in.id_A = std::sqrt(id2 / w);
  in.iq_A = std::copysign(std::sqrt(iq2 / w), iq);
  in.ambient_degC = amb / w;
  in.coolant_degC = cool / w;
  return in;
}

/// Re-discretisation schedule of averaged rows: where the inputs move (by 2 % of current
/// squared or speed, 1 K of a boundary) or the step changes.
std::vector<char> CoarseSchedule(const Grid& g) {
  std::vector<char> out(g.row_t_s.size(), 0);
  std::size_t ref = 0;
  for (std::size_t j = 0; j + 1 < g.row_t_s.size(); ++j) {
    const auto& a = g.in[ref];
    const auto& b = g.in[j];
    const double i2a = a.id_A * a.id_A + a.iq_A * a.iq_A, i2b = b.id_A * b.id_A + b.iq_A * b.iq_A;
    const double dta = ref + 1 < g.row_t_s.size() ? g.row_t_s[ref + 1] - g.row_t_s[ref] : 0.0;
    const double dtb = g.row_t_s[j + 1] - g.row_t_s[j];
    const bool moved =
        j == 0 || std::abs(i2a - i2b) > 0.02 * std::max(i2a, 1.0) ||
        std::abs(a.speed_rpm - b.speed_rpm) > 0.02 * std::max(std::abs(a.speed_rpm), 50.0) ||
        std::abs(a.ambient_degC - b.ambient_degC) > 1.0 ||
        std::abs(a.coolant_degC - b.coolant_degC) > 1.0 || std::abs(dta - dtb) > 1e-6 * dtb;
    if (moved) {
      out[j] = 1;
      ref = j;
    }
  }
  return out;
}

/// Re-discretisation schedule of the data's rows: where `pumptherm simulate`'s discretiser
/// (relative tolerance 1e-4 on the base model's A) redoes exp(A tau). Fixed by the data and the
/// base model, so the simulated series stays a smooth function of the fitted parameters
/// (numeric derivatives need that), and the base model is simulated as `simulate` does.
std::vector<char> ExactSchedule(const Grid& g, const pe::ThermalModel& base) {
  std::vector<char> out(g.row_t_s.size(), 0);
  pe::ThermalLinearModel lin;
  pe::ThermalDiscretiser disc(1e-4);
  for (std::size_t k = 0; k + 1 < g.row_t_s.size(); ++k) {
    base.Linearise(g.in[k], lin);
    out[k] = disc.Update(lin, g.row_t_s[k + 1] - g.row_t_s[k]) ? 1 : 0;
  }
  return out;
}

/// Row by row (exact: the data's rows, inputs held over each, as `pumptherm simulate`) when the
/// data has at most options.max_exact_rows rows; otherwise rows averaged over the grid steps.
Grid MakeGrid(const Data& d, const Options& o, const pe::ThermalModel& base) {
  Grid g;
  const std::vector<std::size_t> idx = GridPoints(d, o);
  g.averaged = static_cast<long>(d.size()) > o.max_exact_rows;
  for (const auto& m : d.measured) {
    g.nodes.push_back(m.node);
    g.measured.emplace_back();
  }
  for (std::size_t j = 0; j < idx.size(); ++j) {
    g.t_s.push_back(d.time_s[idx[j]]);
    for (std::size_t i = 0; i < d.measured.size(); ++i)
      g.measured[i].push_back(d.measured[i].value_degC[idx[j]]);
  }
  if (g.averaged) {
    for (std::size_t j = 0; j < idx.size(); ++j) {
      const std::size_t b = j + 1 < idx.size() ? idx[j + 1] : std::min(idx[j] + 1, d.size());
      g.at.push_back(j);
      g.row_t_s.push_back(d.time_s[idx[j]]);
      g.in.push_back(AverageInputs(d, idx[j], b));
    }
    g.rediscretise = CoarseSchedule(g);
  } else {
    g.at = idx;
    g.row_t_s.assign(d.time_s.begin(), d.time_s.begin() + static_cast<long>(idx.back()) + 1);
    for (std::size_t k = 0; k <= idx.back(); ++k) g.in.push_back(d.Inputs(k));
    g.rediscretise = ExactSchedule(g, base);
  }
  return g;
}

/// Discretisations by (a, step), matched bit for bit. DiscretiseZoh (a matrix exponential) is
/// most of a simulation's time, and the same a recurs: within a simulation (the measured
/// currents are quantised, and a depends on the inputs alone unless an expression reads a node
/// temperature), across the simulations of a fit whose effect leaves a alone (a loss, a sensor),
/// and across candidates (every fit starts at the input model). Equal arguments give equal
/// results, so a hit changes no simulated value.
class ZohCache {
 public:
  void Discretise(const Eigen::MatrixXd& a_per_s, double dt_s, pe::ThermalDiscreteModel& out) {
    key_.assign(reinterpret_cast<const char*>(a_per_s.data()),
                sizeof(double) * static_cast<std::size_t>(a_per_s.size()));
    key_.append(reinterpret_cast<const char*>(&dt_s), sizeof dt_s);
    const auto it = map_.find(key_);
    if (it != map_.end()) {
      out = it->second;
      return;
    }
    pe::DiscretiseZoh(a_per_s, dt_s, out);
    // Bounded memory (about 1.3 kB an entry for 7 states): start again when full.
    if (map_.size() >= kMaxEntries) map_.clear();
    map_.emplace(key_, out);
  }

 private:
  static constexpr std::size_t kMaxEntries = 8192;
  std::string key_;
  std::unordered_map<std::string, pe::ThermalDiscreteModel> map_;
};

using NodeSeries = std::vector<std::vector<double>>;  ///< [node][grid point]

/// Simulate(...)'s results of one run by grid and model effects (names and values, bit for
/// bit), and the run's ZohCache. A run simulates the same network many times: every sensor
/// candidate's fit and the final scores simulate the current model's network again, and a fit
/// evaluates some parameter values more than once (in Ceres's iterations, then for the
/// covariance and the scores at the solution). The same model text on the same grid simulates
/// to the same values, so a hit changes no result.
class SimulationCache {
 public:
  ZohCache zoh;

  /// The series of the model with `model_effects` on `g`; `simulate` makes it when it is not
  /// held (and may throw: nothing is kept then).
  const NodeSeries& Get(const void* g, const std::vector<pe::Effect>& model_effects,
                        const std::function<NodeSeries()>& simulate) {
    std::string key(reinterpret_cast<const char*>(&g), sizeof g);
    for (const pe::Effect& e : model_effects) {
      key += e.name;
      key += '\0';
      key.append(reinterpret_cast<const char*>(e.values.data()), sizeof(double) * e.values.size());
      key += '\0';
    }
    const auto it = map_.find(key);
    if (it != map_.end()) return it->second;
    NodeSeries s = simulate();
    std::size_t bytes = key.size();
    for (const auto& v : s) bytes += sizeof(double) * v.size();
    // Bounded memory: start again when full.
    if (bytes_ + bytes > kMaxBytes) {
      map_.clear();
      bytes_ = 0;
    }
    bytes_ += bytes;
    return map_.emplace(std::move(key), std::move(s)).first->second;
  }

 private:
  static constexpr std::size_t kMaxBytes = std::size_t{128} << 20;
  std::size_t bytes_ = 0;
  std::unordered_map<std::string, NodeSeries> map_;
};

/// Simulates `model` over the grid's rows; returns the measured nodes' temperatures at the grid
/// points [node][j].
std::vector<std::vector<double>> Simulate(const pe::ThermalModel& model, const Grid& g,
                                          ZohCache& zoh) {
  const int n = model.StateCount();
  std::vector<int> state(g.nodes.size()), all(g.nodes.size());
  bool need_all = false;
  for (std::size_t i = 0; i < g.nodes.size(); ++i) {
    state[i] = model.StateIndex(g.nodes[i]);
    for (std::size_t a = 0; a < model.Nodes().size(); ++a)
      if (model.Nodes()[a].name == g.nodes[i]) all[i] = static_cast<int>(a);
    need_all = need_all || state[i] < 0;
  }
  // Start: a cold start (every measured node within 2 K of ambient) starts every node at
  // ambient; otherwise measured states start at their first reading, the others at the mean.
  const double amb0 = g.in[0].ambient_degC;
  bool cold = true;
  double mean0 = 0.0;
  for (const auto& m : g.measured) {
    cold = cold && std::abs(m[0] - amb0) < 2.0;
    mean0 += m[0] / static_cast<double>(g.measured.size());
  }
  Eigen::VectorXd x = Eigen::VectorXd::Constant(n, cold ? amb0 : mean0);
  if (!cold)
    for (std::size_t i = 0; i < g.nodes.size(); ++i)
      if (state[i] >= 0) x(state[i]) = g.measured[i][0];

  std::vector<std::vector<double>> out(g.nodes.size(), std::vector<double>(g.t_s.size()));
  pe::ThermalLinearModel lin;
  pe::ThermalDiscreteModel disc;
  Eigen::VectorXd next(n);
  // Massless nodes from the row's own inputs (the point's inputs, as `simulate` writes them).
  auto record = [&](std::size_t j, const pe::ThermalInputs& in) {
    Eigen::VectorXd full;
    if (need_all) full = model.AllTemperatures_degC(in, x);
    for (std::size_t i = 0; i < g.nodes.size(); ++i)
      out[i][j] = state[i] >= 0 ? x(state[i]) : full(all[i]);
  };
  record(0, g.in[0]);
  std::size_t j = 1;
  for (std::size_t k = 0; j < g.at.size(); ++k) {
    model.Linearise(g.in[k], x, lin);
    if (g.rediscretise[k]) zoh.Discretise(lin.a_per_s, g.row_t_s[k + 1] - g.row_t_s[k], disc);
    next.noalias() = disc.ad * x + disc.phi_s * lin.f_K_per_s;
    x = next;
    if (k + 1 == g.at[j]) record(j++, g.in[g.averaged ? k : k + 1]);
  }
  return out;
}

/// The model plus a list of effects whose (single) parameters are the fit's unknowns,
/// value_e = neutral_e + typical_e p_e.
class Evaluator {
 public:
  Evaluator(const std::string& text, const std::string& source, const pe::ThermalModelFiles& files,
            std::vector<pe::Effect> effects, SimulationCache& simulations)
      : text_(text),
        source_(source),
        files_(files),
        effects_(std::move(effects)),
        simulations_(&simulations) {
    for (const auto& e : effects_) specs_.push_back(pe::FindEffect(e.name));
  }
  std::size_t size() const { return effects_.size(); }
  double Value(std::size_t e, double p) const {
    return specs_[e]->parameters[0].neutral + specs_[e]->parameters[0].typical * p;
  }
  double Internal(std::size_t e, double v) const {
    return (v - specs_[e]->parameters[0].neutral) / specs_[e]->parameters[0].typical;
  }
  const pe::EffectSpec& Spec(std::size_t e) const { return *specs_[e]; }
  std::vector<pe::Effect> EffectsAt(const double* p) const {
    std::vector<pe::Effect> out = effects_;
    for (std::size_t e = 0; e < out.size(); ++e) out[e].values = {Value(e, p[e])};
    return out;
  }

  /// Simulated measured series on `g` at internal parameters p. The network part comes from the
  /// run's SimulationCache, so changing only sensor parameters costs no simulation.
  std::vector<std::vector<double>> Series(const double* p, const Grid& g) {
    std::vector<pe::Effect> model_effects, sensor_effects;
    for (const pe::Effect& e : EffectsAt(p))
      (pe::FindEffect(e.name)->sensor ? sensor_effects : model_effects).push_back(e);
    std::vector<std::vector<double>> s = simulations_->Get(&g, model_effects, [&] {
      const pe::ThermalModel m = pe::ThermalModel::Parse(
          pe::ApplyModelEffects(text_, source_, model_effects), source_, files_);
      return Simulate(m, g, simulations_->zoh);
    });
    for (const pe::Effect& e : sensor_effects)
      for (std::size_t i = 0; i < g.nodes.size(); ++i)
        if (g.nodes[i] == e.node) pe::ApplySensorEffect(e, g.t_s, s[i]);
    return s;
  }

 private:
  std::string text_, source_;
  pe::ThermalModelFiles files_;
  std::vector<pe::Effect> effects_;
  std::vector<const pe::EffectSpec*> specs_;
  SimulationCache* simulations_;
};

/// Residuals simulated - measured, every node, grid points 1.. (point 0 is the start).
std::vector<double> Residuals(const std::vector<std::vector<double>>& sim, const Grid& g) {
  std::vector<double> r;
  for (std::size_t i = 0; i < g.nodes.size(); ++i)
    for (std::size_t j = 1; j < g.t_s.size(); ++j) r.push_back(sim[i][j] - g.measured[i][j]);
  return r;
}

struct Stats {
  double ssr = 0.0, rmse = 0.0, rho = 0.0, n_eff = 0.0;
  std::size_t n = 0;
};

/// Sum of squares and the pooled lag-1 autocorrelation rho of the residuals, per node series;
/// effective sample size n_eff = n (1 - rho) / (1 + rho) (the variance inflation of an AR(1)
/// process: Bartlett 1946; Bayley & Hammersley 1946), rho clamped to [0, 0.999].
Stats ResidualStats(const std::vector<double>& r, std::size_t nodes) {
  Stats s;
  s.n = r.size();
  const std::size_t per = nodes ? r.size() / nodes : 0;
  double num = 0.0, den = 0.0;
  for (std::size_t i = 0; i < nodes; ++i) {
    double mean = 0.0;
    for (std::size_t j = 0; j < per; ++j) mean += r[i * per + j] / static_cast<double>(per);
    for (std::size_t j = 0; j < per; ++j) {
      const double a = r[i * per + j] - mean;
      den += a * a;
      if (j > 0) num += a * (r[i * per + j - 1] - mean);
    }
  }
  for (double v : r) s.ssr += v * v;
  s.rmse = std::sqrt(s.ssr / static_cast<double>(std::max<std::size_t>(s.n, 1)));
  s.rho = den > 0.0 ? std::clamp(num / den, 0.0, 0.999) : 0.0;
  s.n_eff = std::max(2.0, static_cast<double>(s.n) * (1.0 - s.rho) / (1.0 + s.rho));
  return s;
}

std::vector<NodeGap> Gaps(const std::vector<std::vector<double>>& sim, const Grid& g) {
  std::vector<NodeGap> out;
  NodeGap all{"overall", 0.0, 0.0};
  std::size_t count = 0;
  for (std::size_t i = 0; i < g.nodes.size(); ++i) {
    NodeGap ng{g.nodes[i], 0.0, 0.0};
    for (std::size_t j = 1; j < g.t_s.size(); ++j) {
      const double e = sim[i][j] - g.measured[i][j];
      ng.rmse_K += e * e;
      ng.max_abs_K = std::max(ng.max_abs_K, std::abs(e));
    }
    all.rmse_K += ng.rmse_K;
    count += g.t_s.size() - 1;
    ng.rmse_K = std::sqrt(ng.rmse_K / static_cast<double>(g.t_s.size() - 1));
    all.max_abs_K = std::max(all.max_abs_K, ng.max_abs_K);
    out.push_back(ng);
  }
  all.rmse_K = std::sqrt(all.rmse_K / static_cast<double>(std::max<std::size_t>(count, 1)));
  out.push_back(all);
  return out;
}

struct Functor {
  Evaluator* ev;
  const Grid* g;
  int* evaluations;
  bool operator()(double const* const* p, double* residuals) const {
    ++*evaluations;
    try {
      const std::vector<double> r = Residuals(ev->Series(p[0], *g), *g);
      std::copy(r.begin(), r.end(), residuals);
      return std::all_of(r.begin(), r.end(), [](double v) { return std::isfinite(v); });
    } catch (const std::exception&) {
      return false;  // a singular or unstable network at these values: Ceres steps back
    }
  }
};

struct FitResult {
  std::vector<double> p;
  std::vector<double> sd;  ///< standard deviation of each value (physical units), NaN if unknown
  Stats stats;
  std::vector<std::vector<double>> train_series;
  int evaluations = 0;
};

FitResult Fit(Evaluator& ev, std::vector<double> p0, const Grid& g, const Options& o) {
  FitResult fr;
  fr.p = std::move(p0);
  const std::size_t k = fr.p.size();
  const std::size_t n_res = g.nodes.size() * (g.t_s.size() - 1);
  if (k > 0) {
    ceres::NumericDiffOptions nd;
    nd.relative_step_size = 1e-3;
    auto* cost = new ceres::DynamicNumericDiffCostFunction<Functor, ceres::CENTRAL>(
        new Functor{&ev, &g, &fr.evaluations}, ceres::TAKE_OWNERSHIP, nd);
    cost->AddParameterBlock(static_cast<int>(k));
    cost->SetNumResiduals(static_cast<int>(n_res));
    ceres::Problem problem;
    problem.AddResidualBlock(cost, nullptr, fr.p.data());
    for (std::size_t e = 0; e < k; ++e) {
      const auto& ps = ev.Spec(e).parameters[0];
      problem.SetParameterLowerBound(fr.p.data(), static_cast<int>(e), ev.Internal(e, ps.lower));
      problem.SetParameterUpperBound(fr.p.data(), static_cast<int>(e), ev.Internal(e, ps.upper));
    }
    ceres::Solver::Options so;
    so.linear_solver_type = ceres::DENSE_QR;
    so.max_num_iterations = o.max_fit_iterations;
    so.function_tolerance = 1e-7;
    so.parameter_tolerance = 1e-6;
    so.logging_type = ceres::SILENT;
    ceres::Solver::Summary summary;
    ceres::Solve(so, &problem, &summary);

    fr.train_series = ev.Series(fr.p.data(), g);
    fr.stats = ResidualStats(Residuals(fr.train_series, g), g.nodes.size());
    // Covariance of the estimates: (J'J)^-1 s^2 inflated by n / n_eff for the residuals'
    // autocorrelation; s^2 = SSR / (n - k).
    ceres::Covariance::Options co;
    co.algorithm_type = ceres::DENSE_SVD;
    co.null_space_rank = -1;
    ceres::Covariance cov(co);
    std::vector<std::pair<const double*, const double*>> blocks{{fr.p.data(), fr.p.data()}};
    fr.sd.assign(k, std::nan(""));
    if (cov.Compute(blocks, &problem)) {
      std::vector<double> c(k * k);
      cov.GetCovarianceBlock(fr.p.data(), fr.p.data(), c.data());
      const double s2 = fr.stats.ssr / std::max(1.0, static_cast<double>(n_res - k));
      const double inflation = static_cast<double>(n_res) / fr.stats.n_eff;
      for (std::size_t e = 0; e < k; ++e)
        if (c[e * k + e] > 0.0)
          fr.sd[e] = ev.Spec(e).parameters[0].typical * std::sqrt(c[e * k + e] * s2 * inflation);
    }
  } else {
    fr.train_series = ev.Series(fr.p.data(), g);
    fr.stats = ResidualStats(Residuals(fr.train_series, g), g.nodes.size());
  }
  return fr;
}

std::string Label(const pe::Effect& e) {
  return e.node.empty() ? e.name : e.name + "(" + e.node + ")";
}

/// RMSE between two simulations on the same grid points (every node, points 1..).
double SeriesRmse(const std::vector<std::vector<double>>& a,
                  const std::vector<std::vector<double>>& b) {
  double ss = 0.0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < a.size(); ++i)
    for (std::size_t j = 1; j < a[i].size(); ++j, ++n)
      ss += (a[i][j] - b[i][j]) * (a[i][j] - b[i][j]);
  return n ? std::sqrt(ss / static_cast<double>(n)) : 0.0;
}

/// The cost of averaging: the base model row by row against `averaged` on the same points.
double AveragingCost(const pe::ThermalModel& base, const Data& d, const Options& o,
                     const std::vector<std::vector<double>>& averaged) {
  Options exact = o;
  exact.max_exact_rows = static_cast<long>(d.size());
  ZohCache zoh;
  return SeriesRmse(Simulate(base, MakeGrid(d, exact, base), zoh), averaged);
}

}  // namespace

Simulated SimulateModel(const pe::ThermalModel& model, const Data& data, const Options& options) {
  const Grid g = MakeGrid(data, options, model);
  ZohCache zoh;
  return {g.t_s, g.nodes, Simulate(model, g, zoh), g.averaged};
}

std::string ShortestFloats(std::string_view toml) {
  std::string out;
  out.reserve(toml.size());
  auto word_char = [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.' ||
           c == '+';
  };
  std::size_t i = 0;
  while (i < toml.size()) {
    const char c = toml[i];
    if (c == '#') {  // a comment, to the end of the line
      const std::size_t e = toml.find('\n', i);
      const std::size_t end = e == std::string_view::npos ? toml.size() : e;
      out.append(toml.substr(i, end - i));
      i = end;
    } else if (c == '"' || c == '\'') {  // a string (basic strings may escape their quote)
      std::size_t j = i + 1;
      while (j < toml.size() && toml[j] != c) j += (c == '"' && toml[j] == '\\') ? 2 : 1;
      j = std::min(j + 1, toml.size());
      out.append(toml.substr(i, j - i));
      i = j;
    } else if (word_char(c)) {  // a bare key, a number, a boolean: one token
      std::size_t j = i;
      while (j < toml.size() && word_char(toml[j])) ++j;
      const std::string_view token = toml.substr(i, j - i);
      double v = 0.0;
      const char* first = token.data() + (token.front() == '+' ? 1 : 0);
      const auto [ptr, ec] = std::from_chars(first, token.data() + token.size(), v);
      const bool numeric = std::isdigit(static_cast<unsigned char>(c)) || c == '-' || c == '+';
      const bool is_float = token.find_first_of(".eE") != std::string_view::npos;
      if (numeric && is_float && ec == std::errc() && ptr == token.data() + token.size() &&
          std::isfinite(v)) {
        std::string shortest = fmt::format("{}", v);
        if (shortest.find_first_of(".eE") == std::string::npos) shortest += ".0";
        out += shortest;
      } else {
        out.append(token);
      }
      i = j;
    } else {
      out += c;
      ++i;
    }
  }
  return out;
}

std::string SeparatingExperiment(const std::vector<std::string>& effects) {
  static const std::map<std::string, std::string> kHow{
      {"frame_thermal_mass",
       "a load step held longer than the frame's time constant, then a cool-down (heat capacity "
       "shapes the transient, not the steady state)"},
      {"frame_ambient_resistance",
       "steady states at two or more loss levels (the frame's rise over ambient per watt)"},
      {"speed_dependent_cooling",
       "the same losses at two speeds, e.g. a current step at standstill and at full speed"},
      {"winding_conductance", "current steps with both slot and end winding measured"},
      {"copper_temperature_coefficient",
       "the same current from a cold and from a warm start (the copper loss grows with "
       "temperature)"},
      {"iron_loss_scale", "speed steps at zero current (iron loss alone, in the stator)"},
      {"rotor_loss", "speed steps at zero current with the rotor temperature measured"},
      {"sensor_lag", "fast load steps sampled at 1 Hz (a sensor lag shows in the first minute)"},
      {"sensor_offset",
       "a long soak at standstill (every node settles to ambient; an offset remains)"},
  };
  std::string out;
  std::vector<std::string> seen;
  for (const std::string& label : effects) {
    const std::string name = label.substr(0, label.find('('));
    if (std::find(seen.begin(), seen.end(), name) != seen.end()) continue;
    seen.push_back(name);
    const auto it = kHow.find(name);
    if (it == kHow.end()) continue;
    out += (out.empty() ? "" : "; ") + name + ": " + it->second;
  }
  return out;
}

Result Run(const std::string& text, const std::string& source, const Data& train,
           const Data& validate, const Options& o, const pe::ThermalModelFiles& files) {
  const auto start = std::chrono::steady_clock::now();
  auto progress = [&](const std::string& s) {
    if (o.progress) o.progress(s);
  };
  const pe::ThermalModel base = pe::ThermalModel::Parse(text, source, files);
  for (const Data* d : {&train, &validate})
    for (const auto& m : d->measured)
      if (std::none_of(base.Nodes().begin(), base.Nodes().end(),
                       [&](const auto& n) { return n.name == m.node; }))
        throw std::invalid_argument(
            fmt::format("{}: node {} is not in the model", d->source, m.node));
  const Grid gt = MakeGrid(train, o, base);
  const Grid gv = MakeGrid(validate, o, base);
  const pe::EffectTargets targets = pe::FindEffectTargets(text, source);

  // Candidate list: model effects once, sensor effects once per node measured in both sets.
  std::vector<pe::Effect> pool;
  std::vector<Candidate> not_applicable;
  for (const pe::EffectSpec& spec : pe::EffectVocabulary()) {
    if (!o.effects.empty() &&
        std::find(o.effects.begin(), o.effects.end(), spec.name) == o.effects.end())
      continue;
    if (spec.sensor) {
      for (const std::string& node : gt.nodes)
        if (std::find(gv.nodes.begin(), gv.nodes.end(), node) != gv.nodes.end())
          pool.push_back({spec.name, {spec.parameters[0].neutral}, node});
      continue;
    }
    if (const std::string why = pe::EffectNotApplicable(spec, targets); !why.empty()) {
      Candidate c;
      c.effect = c.label = spec.name;
      c.not_applicable = why;
      not_applicable.push_back(c);
      continue;
    }
    pool.push_back({spec.name, {spec.parameters[0].neutral}, {}});
  }
  for (const std::string& name : o.effects)
    if (pe::FindEffect(name) == nullptr)
      throw std::invalid_argument("unknown effect '" + name + "'");

  Result res;
  std::vector<pe::Effect> added;  // with their fitted values
  SimulationCache simulations;    // shared by every simulation of this run
  Evaluator base_ev(text, source, files, {}, simulations);
  FitResult current = Fit(base_ev, {}, gt, o);
  const auto before_train = current.train_series;
  const auto before_val = base_ev.Series(nullptr, gv);
  double current_val_rmse = ResidualStats(Residuals(before_val, gv), gv.nodes.size()).rmse;
  if (gt.averaged || gv.averaged) {
    res.simulation = "averaged";
    if (gt.averaged) res.averaging_cost_train_K = AveragingCost(base, train, o, before_train);
    if (gv.averaged) res.averaging_cost_validate_K = AveragingCost(base, validate, o, before_val);
    progress(
        fmt::format("inputs averaged over grid steps: costs {:.3f} K RMSE on train, {:.3f} K on "
                    "validate (input model against row by row)",
                    res.averaging_cost_train_K, res.averaging_cost_validate_K));
  }
  progress(fmt::format("model {}: gap train RMSE {:.3f} K, validate RMSE {:.3f} K", source,
                       current.stats.rmse, current_val_rmse));

  for (int round = 0; round < o.max_effects; ++round) {
    Round rd;
    rd.base_train_rmse_K = current.stats.rmse;
    rd.base_validate_rmse_K = current_val_rmse;
    std::vector<FitResult> fits;
    std::vector<std::vector<pe::Effect>> fitted_effects;
    std::size_t tried = 0;
    for (const pe::Effect& cand : pool) {
      ++tried;
      if (std::any_of(added.begin(), added.end(),
                      [&](const pe::Effect& a) { return Label(a) == Label(cand); }))
        continue;
      std::vector<pe::Effect> effects = added;
      effects.push_back(cand);
      Evaluator ev(text, source, files, effects, simulations);
      std::vector<double> p0;
      for (std::size_t e = 0; e < effects.size(); ++e)
        p0.push_back(ev.Internal(e, effects[e].values[0]));
      Candidate c;
      c.effect = cand.name;
      c.node = cand.node;
      c.label = Label(cand);
      FitResult fr = Fit(ev, p0, gt, o);
      c.evaluations = fr.evaluations;
      const auto val_series = ev.Series(fr.p.data(), gv);
      c.train_rmse_K = fr.stats.rmse;
      c.validate_rmse_K = ResidualStats(Residuals(val_series, gv), gv.nodes.size()).rmse;
      c.rho = fr.stats.rho;
      c.n_eff = fr.stats.n_eff;
      // Information criterion at the candidate's effective sample size (one more parameter).
      c.delta_ic =
          c.n_eff * std::log(std::max(fr.stats.ssr, 1e-300) / std::max(current.stats.ssr, 1e-300)) +
          std::log(c.n_eff);
      const std::size_t e = effects.size() - 1;
      const auto& ps = ev.Spec(e).parameters[0];
      FittedParameter fp{ps.name, ev.Value(e, fr.p[e]), std::nan(""), std::nan(""), ps.neutral};
      if (std::isfinite(fr.sd[e])) {
        fp.low95 = fp.value - 1.96 * fr.sd[e];
        fp.high95 = fp.value + 1.96 * fr.sd[e];
        c.significant = fp.low95 > ps.neutral || fp.high95 < ps.neutral;
      }
      c.parameters.push_back(fp);
      c.eligible = c.significant && c.delta_ic <= -o.ic_threshold &&
                   c.validate_rmse_K <= (1.0 - o.min_validation_gain) * current_val_rmse;
      progress(fmt::format(
          "round {} candidate {}/{} {}: train {:.3f} K, validate {:.3f} K, dIC {:.1f}{}", round + 1,
          tried, pool.size(), c.label, c.train_rmse_K, c.validate_rmse_K, c.delta_ic,
          c.eligible ? " (eligible)" : ""));
      rd.candidates.push_back(c);
      fits.push_back(std::move(fr));
      fitted_effects.push_back(ev.EffectsAt(fits.back().p.data()));
    }
    std::vector<std::size_t> order(rd.candidates.size());
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
      return rd.candidates[a].validate_rmse_K < rd.candidates[b].validate_rmse_K;
    });
    std::size_t best = order.size();
    for (std::size_t i : order)
      if (rd.candidates[i].eligible) {
        best = i;
        break;
      }
    if (best == order.size()) {
      rd.verdict = "none";
    } else {
      // A rival within the validation margin blocks the name when it is eligible itself (two
      // credible explanations), or when the best is not clearly better than the current model
      // either (its validation RMSE not below the current one by the margin: the validation data
      // then tell nothing apart). An ineligible rival cannot block a best that is clearly
      // better than the current model (docs/discrepancy.md, "How it decides").
      const Candidate& b = rd.candidates[best];
      const double limit = (1.0 + o.margin) * b.validate_rmse_K;
      const bool clearly_better = current_val_rmse >= limit;
      for (std::size_t i : order) {
        const Candidate& c = rd.candidates[i];
        if (i != best && c.validate_rmse_K < limit && (c.eligible || !clearly_better))
          rd.tied.push_back(c.label);
      }
      if (rd.tied.empty()) {
        rd.verdict = "named";
      } else {
        rd.verdict = "ambiguous";
        rd.tied.insert(rd.tied.begin(), rd.candidates[best].label);
        rd.experiment = SeparatingExperiment(rd.tied);
      }
    }
    progress(fmt::format("round {}: {}{}", round + 1, rd.verdict,
                         rd.verdict == "named" ? " " + rd.candidates[best].label : ""));
    std::vector<Candidate> sorted;
    for (std::size_t i : order) sorted.push_back(rd.candidates[i]);
    for (const Candidate& c : not_applicable) sorted.push_back(c);
    const bool named = rd.verdict == "named";
    res.rounds.push_back(rd);
    res.rounds.back().candidates = sorted;
    if (!named) break;
    added = fitted_effects[best];
    current = std::move(fits[best]);
    current_val_rmse = rd.candidates[best].validate_rmse_K;
    // Every added effect's parameters, re-fitted jointly in this round.
    res.effects.clear();
    Evaluator ev(text, source, files, added, simulations);
    for (std::size_t e = 0; e < added.size(); ++e) {
      AddedEffect ae;
      ae.effect = added[e];
      const auto& ps = ev.Spec(e).parameters[0];
      FittedParameter fp{ps.name, added[e].values[0], std::nan(""), std::nan(""), ps.neutral};
      if (std::isfinite(current.sd[e])) {
        fp.low95 = fp.value - 1.96 * current.sd[e];
        fp.high95 = fp.value + 1.96 * current.sd[e];
      }
      ae.parameters.push_back(fp);
      ae.reading = pe::PhysicalReading(added[e], targets);
      res.effects.push_back(ae);
    }
  }
  res.verdict = res.rounds.empty() ? "none" : res.rounds.front().verdict;

  Evaluator final_ev(text, source, files, added, simulations);
  std::vector<double> pf;
  for (std::size_t e = 0; e < added.size(); ++e)
    pf.push_back(final_ev.Internal(e, added[e].values[0]));
  const auto after_train = final_ev.Series(pf.data(), gt);
  const auto after_val = final_ev.Series(pf.data(), gv);
  res.train_before = Gaps(before_train, gt);
  res.train_after = Gaps(after_train, gt);
  res.validate_before = Gaps(before_val, gv);
  res.validate_after = Gaps(after_val, gv);
  res.model_toml = ShortestFloats(pe::ApplyModelEffects(text, source, added, files.directory));
  res.validate_plot = {gv.t_s, gv.nodes, gv.measured, before_val, after_val};
  res.train_plot = {gt.t_s, gt.nodes, gt.measured, before_train, after_train};
  res.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return res;
}

}  // namespace pumptherm::tools::discrepancy
