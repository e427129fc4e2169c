#include "estimators/thermal_model.hpp"

#include <fmt/core.h>
#include <fmt/format.h>
#include <muParser.h>
#include <toml++/toml.h>

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <deque>
#include <map>
#include <optional>
#include <set>

namespace pumptherm::estimators {
namespace {

constexpr int kAmbient = -1;  ///< edge end / reference code of the ambient boundary
constexpr int kCoolant = -2;  ///< edge end / reference code of the coolant boundary
constexpr double kPi = 3.14159265358979323846;

/// Values the expressions may read. Lives on the heap so that the parsers' pointers stay valid
/// when the model moves.
struct ExpressionVariables {
  double speed_rpm = 0.0;
  double speed_rad_per_s = 0.0;
  double id_A = 0.0;
  double iq_A = 0.0;
  double is_A = 0.0;
  double i2_A2 = 0.0;
  double ambient_C = 25.0;
  double coolant_C = 25.0;
  std::deque<double> node_C;    ///< `<node>_C` of the states (deque: stable addresses)
  std::deque<double> quantity;  ///< values of the input-dependent `[[quantity]]` entries
};

/// A loss map (2-D, over a row axis and a column axis) or curve (1-D) read from a CSV file, and
/// its lookup rule. Outside the grid the value at the nearest edge is taken (no extrapolation).
struct Table {
  std::string name;
  bool linear = true;     ///< linear interpolation, else rounding to the nearest grid point
  std::vector<double> x;  ///< row axis (first column), strictly increasing
  std::vector<double> y;  ///< column axis (header of a map), strictly increasing; empty: curve
  std::vector<double> v;  ///< values, row-major: v[i * max(1, y.size()) + j]

  /// Index and weight of the upper neighbour along `axis` (linear), or the nearest index with
  /// weight 0 (rounding; a tie goes to the point farther from zero, as MATLAB's round does).
  static void Locate(const std::vector<double>& axis, double q, bool linear, std::size_t& i0,
                     double& w) {
    const std::size_t n = axis.size();
    w = 0.0;
    if (n == 1 || q <= axis.front()) {
      i0 = 0;
      return;
    }
    if (q >= axis.back()) {
      i0 = n - 1;
      return;
    }
    const std::size_t hi = static_cast<std::size_t>(std::upper_bound(axis.begin(), axis.end(), q) -
                                                    axis.begin());  // axis[hi-1] <= q < axis[hi]
    const std::size_t lo = hi - 1;
    const double span = axis[hi] - axis[lo];
    const double f = (q - axis[lo]) / span;
    if (linear) {
      i0 = lo;
      w = f;
      return;
    }
    const double mid = 0.5 * (axis[lo] + axis[hi]);
    if (q == mid) {
      i0 = std::abs(axis[hi]) >= std::abs(axis[lo]) ? hi : lo;
    } else {
      i0 = q > mid ? hi : lo;
    }
  }

  double At(std::size_t i, std::size_t j) const {
    return v[i * std::max<std::size_t>(1, y.size()) + j];
  }

  double Curve(double q) const {
    std::size_t i = 0;
    double w = 0.0;
    Locate(x, q, linear, i, w);
    return w == 0.0 ? At(i, 0) : (1.0 - w) * At(i, 0) + w * At(i + 1, 0);
  }

  double Map(double qr, double qc) const {
    std::size_t i = 0, j = 0;
    double wi = 0.0, wj = 0.0;
    Locate(x, qr, linear, i, wi);
    Locate(y, qc, linear, j, wj);
    const std::size_t i1 = wi == 0.0 ? i : i + 1, j1 = wj == 0.0 ? j : j + 1;
    return (1.0 - wi) * ((1.0 - wj) * At(i, j) + wj * At(i, j1)) +
           wi * ((1.0 - wj) * At(i1, j) + wj * At(i1, j1));
  }

  static double CurveCallback(void* self, double q) {
    return static_cast<const Table*>(self)->Curve(q);
  }
  static double MapCallback(void* self, double qr, double qc) {
    return static_cast<const Table*>(self)->Map(qr, qc);
  }
};

/// A number parsed from the whole of `cell` (surrounding blanks allowed).
std::optional<double> ParseNumber(std::string_view cell, bool allow_suffix) {
  std::string s(cell);
  const auto b = s.find_first_not_of(" \t\r");
  if (b == std::string::npos) return std::nullopt;
  s = s.substr(b);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.pop_back();
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (end == s.c_str() || !std::isfinite(v)) return std::nullopt;
  if (!allow_suffix && *end != '\0') return std::nullopt;
  return v;
}

/// Parses a table's CSV text (a header, then rows of numbers). A curve has two columns: x, then
/// the value. A map's first column is the row axis; the header of every further column starts
/// with that column's axis value (a unit may follow: "100rpm"). Throws std::runtime_error naming
/// `where` (the file), the line and the column.
void ParseTableCsv(std::string_view text, const std::string& where, bool map, Table& t) {
  std::vector<std::vector<std::string_view>> rows;
  std::vector<int> lines;
  int line = 0;
  std::size_t pos = 0;
  while (pos < text.size()) {
    std::size_t eol = text.find('\n', pos);
    if (eol == std::string_view::npos) eol = text.size();
    std::string_view l = text.substr(pos, eol - pos);
    pos = eol + 1;
    ++line;
    if (!l.empty() && l.back() == '\r') l.remove_suffix(1);
    if (l.find_first_not_of(" \t") == std::string_view::npos) continue;
    std::vector<std::string_view> cells;
    std::size_t c = 0;
    while (true) {
      const std::size_t comma = l.find(',', c);
      cells.push_back(
          l.substr(c, comma == std::string_view::npos ? std::string_view::npos : comma - c));
      if (comma == std::string_view::npos) break;
      c = comma + 1;
    }
    rows.push_back(std::move(cells));
    lines.push_back(line);
  }
  auto fail = [&](int l, std::size_t col, const std::string& what) {
    throw std::runtime_error(fmt::format("{}:{}: column {}: {}", where, l, col + 1, what));
  };
  if (rows.size() < 2)
    throw std::runtime_error(fmt::format("{}: needs a header and at least one row", where));
  const std::size_t cols = rows[0].size();
  if (!map && cols != 2)
    fail(lines[0], 0, fmt::format("a curve has 2 columns (x, value), found {}", cols));
  if (map && cols < 2) fail(lines[0], 0, "a map needs the row axis and at least one value column");
  if (map) {
    for (std::size_t j = 1; j < cols; ++j) {
      auto v = ParseNumber(rows[0][j], true);
      if (!v)
        fail(lines[0], j,
             fmt::format("header '{}' does not start with the column's axis value", rows[0][j]));
      if (!t.y.empty() && !(*v > t.y.back()))
        fail(lines[0], j, "column axis values must increase strictly");
      t.y.push_back(*v);
    }
  }
  for (std::size_t r = 1; r < rows.size(); ++r) {
    if (rows[r].size() != cols) {
      fail(lines[r], std::min(rows[r].size(), cols) - 1,
           fmt::format("{} cells where the header has {}", rows[r].size(), cols));
    }
    for (std::size_t j = 0; j < cols; ++j) {
      auto v = ParseNumber(rows[r][j], false);
      if (!v) fail(lines[r], j, fmt::format("'{}' is not a finite number", rows[r][j]));
      if (j == 0) {
        if (!t.x.empty() && !(*v > t.x.back()))
          fail(lines[r], j, "row axis values must increase strictly");
        t.x.push_back(*v);
      } else {
        t.v.push_back(*v);
      }
    }
  }
}

/// `directory`/`path` as text (no file system access); absolute paths unchanged.
std::string JoinPath(const std::string& directory, const std::string& path) {
  if (path.empty() || path.front() == '/' || directory.empty()) return path;
  return directory.back() == '/' ? directory + path : directory + "/" + path;
}

/// A number, or a muParser expression of the parameters and (where allowed) the inputs.
struct Expression {
  double value = 0.0;                  ///< the value when constant
  std::unique_ptr<mu::Parser> parser;  ///< set only when the expression reads an input
  std::string text;
  bool reads_nodes = false;       ///< reads a node temperature `<node>_C`
  bool reads_speed = false;       ///< reads `speed_rpm` or `speed_rad_per_s`
  bool reads_currents = false;    ///< reads `id_A`, `iq_A`, `is_A` or `i2_A2`
  bool reads_boundaries = false;  ///< reads `ambient_C` or `coolant_C`

  bool Varies() const { return parser != nullptr; }
  double Eval() const { return parser ? parser->Eval() : value; }
};

struct Edge {
  int a = 0, b = 0;  ///< node indices, or kAmbient / kCoolant
  Expression resistance_K_per_W;
  int line = 0;
  std::string label;
};

struct LossTerm {
  std::string name;
  int line = 0;
  Expression power_W;
  double alpha_per_K = 0.0;
  std::vector<int> temperature_states;  ///< averaged; empty when alpha is zero
  int reference = 0;                    ///< kAmbient / kCoolant, or 0 for reference_degC
  double reference_degC = 0.0;
  std::vector<std::pair<int, double>> shares;  ///< (node index, share)
  /// The power at rest (speed and currents zero) when that is a constant: the expression reads
  /// no node temperature and no boundary.
  std::optional<double> power_at_rest_W;
};

/// The Kron-reduced network (eq. S25) for one set of resistance values.
struct Reduced {
  Eigen::MatrixXd a_red;  ///< n x n, W/K: Y11 - Y12 Y22^-1 Y21
  Eigen::MatrixXd b_b;    ///< n x 2, W/K: boundary coupling after reduction (ambient, coolant)
  Eigen::MatrixXd g;      ///< n x N: loss of every node onto the states
  Eigen::MatrixXd m_z;    ///< Nz x n: massless temperatures from the states (-Y22^-1 Y21)
  Eigen::MatrixXd m_zb;   ///< Nz x 2: massless temperatures from the boundaries
  Eigen::MatrixXd g_z;    ///< Nz x N: massless temperatures from the losses
};

std::string Where(const std::string& source, int line) {
  return fmt::format("{}:{}", source, line);
}

int LineOf(const toml::node& n) { return static_cast<int>(n.source().begin.line); }

}  // namespace

struct ThermalModel::Impl {
  std::string source;
  std::string name;
  std::unique_ptr<ExpressionVariables> vars = std::make_unique<ExpressionVariables>();
  std::map<std::string, double> parameters;
  std::optional<ThermalOperatingRange> operating_range;
  std::vector<ThermalNodeInfo> nodes;
  std::vector<int> state_of_node;  ///< -1 for massless
  std::vector<int> massless_of_node;
  std::vector<int> node_of_state;
  std::vector<int> node_of_massless;
  std::vector<std::string> state_names;
  Eigen::VectorXd capacity_J_per_K;
  Eigen::VectorXd inv_capacity;
  std::vector<Edge> edges;
  std::vector<LossTerm> losses;
  std::vector<std::unique_ptr<Table>> tables;  ///< unique_ptr: muParser holds their addresses
  struct Quantity {
    std::string name;
    Expression value;
    double* slot = nullptr;  ///< in vars->quantity when the value varies
  };
  std::vector<Quantity> quantities;
  bool uses_node_temperatures = false;
  bool uses_coolant = false;
  bool resistances_vary = false;
  Eigen::VectorXd winding_weights;
  Reduced cached;  ///< valid when !resistances_vary
  /// Per loss (columns), the states' heat rate per watt, K/(s W): C^-1 G times the loss's
  /// shares, for the cached network.
  Eigen::MatrixXd loss_rate_per_W;
  // Scratch for Linearise (mutable: Linearise is logically const).
  mutable Reduced scratch;
  mutable Eigen::VectorXd p0;
  mutable Eigen::MatrixXd d;
  mutable std::vector<double> power_W;  ///< per loss, at the inputs of the last Linearise
  /// The last linearisation and its inputs, kept where the result depends on the inputs alone
  /// (constant resistances, no expression reading a node temperature): the pump's filters
  /// linearise at the same inputs several times per period.
  mutable ThermalLinearModel last_lin;
  mutable ThermalInputs last_in;
  mutable bool last_valid = false;
  mutable ThermalLinearModel still_scratch, rest_scratch;

  int N() const { return static_cast<int>(nodes.size()); }
  int n() const { return static_cast<int>(node_of_state.size()); }
  int nz() const { return static_cast<int>(node_of_massless.size()); }

  std::string EndName(int e) const {
    if (e == kAmbient) return "ambient";
    if (e == kCoolant) return "coolant";
    return nodes[static_cast<std::size_t>(e)].name;
  }

  [[noreturn]] void Fail(int line, const std::string& what) const {
    throw ThermalModelError(fmt::format("{}: {}", Where(source, line), what));
  }

  /// Which kinds of variable `e` reads through `var` (a quantity: what its value reads).
  void MarkReads(const std::string& var, Expression& e) const {
    for (const std::string& st : state_names) e.reads_nodes = e.reads_nodes || var == st + "_C";
    e.reads_speed = e.reads_speed || var == "speed_rpm" || var == "speed_rad_per_s";
    e.reads_currents =
        e.reads_currents || var == "id_A" || var == "iq_A" || var == "is_A" || var == "i2_A2";
    e.reads_boundaries = e.reads_boundaries || var == "ambient_C" || var == "coolant_C";
    for (const Quantity& q : quantities) {
      if (var != q.name) continue;
      e.reads_nodes = e.reads_nodes || q.value.reads_nodes;
      e.reads_speed = e.reads_speed || q.value.reads_speed;
      e.reads_currents = e.reads_currents || q.value.reads_currents;
      e.reads_boundaries = e.reads_boundaries || q.value.reads_boundaries;
    }
  }

  Expression Compile(const toml::node& n, const std::string& key, bool inputs_allowed) const {
    Expression e;
    if (auto v = n.value<double>()) {
      e.value = *v;
      e.text = fmt::format("{}", *v);
    } else if (auto s = n.value<std::string>()) {
      e.text = *s;
      auto p = std::make_unique<mu::Parser>();
      try {
        for (const auto& [k, val] : parameters) p->DefineConst(k, val);
        for (const auto& t : tables) {
          if (t->y.empty()) {
            p->DefineFunUserData(t->name, &Table::CurveCallback, t.get());
          } else {
            p->DefineFunUserData(t->name, &Table::MapCallback, t.get());
          }
        }
        for (const Quantity& q : quantities) {
          if (q.slot) {
            if (inputs_allowed) p->DefineVar(q.name, q.slot);
          } else {
            p->DefineConst(q.name, q.value.value);
          }
        }
        if (inputs_allowed) {
          for (int st = 0; st < static_cast<int>(node_of_state.size()); ++st) {
            p->DefineVar(state_names[static_cast<std::size_t>(st)] + "_C",
                         &vars->node_C[static_cast<std::size_t>(st)]);
          }
          p->DefineVar("speed_rpm", &vars->speed_rpm);
          p->DefineVar("speed_rad_per_s", &vars->speed_rad_per_s);
          p->DefineVar("id_A", &vars->id_A);
          p->DefineVar("iq_A", &vars->iq_A);
          p->DefineVar("is_A", &vars->is_A);
          p->DefineVar("i2_A2", &vars->i2_A2);
          p->DefineVar("ambient_C", &vars->ambient_C);
          p->DefineVar("coolant_C", &vars->coolant_C);
        }
        p->SetExpr(*s);
        e.value = p->Eval();
        const auto used = p->GetUsedVar();
        for (const auto& [used_name, ptr] : used) MarkReads(used_name, e);
        if (!used.empty()) e.parser = std::move(p);
      } catch (const mu::Parser::exception_type& err) {
        Fail(LineOf(n),
             fmt::format("key '{}': expression \"{}\": {} (at position {}){}", key, *s,
                         err.GetMsg(), err.GetPos() + 1,
                         inputs_allowed ? "" : " (only parameters and tables may be used here)"));
      }
    } else {
      Fail(LineOf(n), fmt::format("key '{}' must be a number or an expression string", key));
    }
    if (!std::isfinite(e.value)) {
      Fail(LineOf(n), fmt::format("key '{}' is not finite ({})", key, e.value));
    }
    return e;
  }

  void SetInputs(const ThermalInputs& in) const {
    if (!std::isfinite(in.speed_rpm) || !std::isfinite(in.id_A) || !std::isfinite(in.iq_A) ||
        !std::isfinite(in.ambient_degC) || (uses_coolant && !std::isfinite(in.coolant_degC))) {
      throw std::domain_error("thermal model inputs must be finite");
    }
    vars->speed_rpm = in.speed_rpm;
    vars->speed_rad_per_s = in.speed_rpm * 2.0 * kPi / 60.0;
    vars->id_A = in.id_A;
    vars->iq_A = in.iq_A;
    vars->is_A = std::sqrt(in.id_A * in.id_A + in.iq_A * in.iq_A);
    vars->i2_A2 = PhaseCurrentSquareSum_A2(in.id_A, in.iq_A);
    vars->ambient_C = in.ambient_degC;
    vars->coolant_C = uses_coolant ? in.coolant_degC : in.ambient_degC;
    EvaluateQuantities();
  }

  /// Sets the node temperatures that expressions read (`<node>_C`).
  void SetTemperatures(const Eigen::VectorXd& x_degC) const {
    if (x_degC.size() != n() || !x_degC.allFinite()) {
      throw std::domain_error("thermal model: state temperatures must be finite, one per state");
    }
    for (int st = 0; st < n(); ++st) vars->node_C[static_cast<std::size_t>(st)] = x_degC(st);
  }

  /// `[[quantity]]` values in file order (each may read the ones before it).
  void EvaluateQuantities() const {
    for (const Quantity& q : quantities) {
      if (q.slot) *q.slot = q.value.Eval();
    }
  }

  double Boundary(int code) const { return code == kAmbient ? vars->ambient_C : vars->coolant_C; }

  /// Workspace of Reduce: sized on first use, so re-assembling a network with input-dependent
  /// resistances allocates nothing afterwards unless it has massless nodes (their LU inverse
  /// allocates).
  struct ReduceScratch {
    Eigen::MatrixXd y, yb, y11, y12, y21, y22, b1, b2, sel_x, sel_z;
  };
  mutable ReduceScratch rs;

  /// Assembles KCL and reduces it (eq. S25) at the current variable values.
  bool Reduce(Reduced& r) const {
    const int nn = N(), ns = n(), nm = nz();
    rs.y.setZero(nn, nn);
    rs.yb.setZero(nn, 2);
    Eigen::MatrixXd& y = rs.y;
    Eigen::MatrixXd& yb = rs.yb;
    for (const Edge& e : edges) {
      const double g = 1.0 / e.resistance_K_per_W.Eval();
      if (e.b < 0) {
        y(e.a, e.a) -= g;
        yb(e.a, -e.b - 1) += g;
      } else {
        y(e.a, e.a) -= g;
        y(e.b, e.b) -= g;
        y(e.a, e.b) += g;
        y(e.b, e.a) += g;
      }
    }
    rs.y11.resize(ns, ns);
    rs.y12.resize(ns, nm);
    rs.y21.resize(nm, ns);
    rs.y22.resize(nm, nm);
    rs.b1.resize(ns, 2);
    rs.b2.resize(nm, 2);
    for (int i = 0; i < ns; ++i) {
      const int ni = node_of_state[i];
      for (int j = 0; j < ns; ++j) rs.y11(i, j) = y(ni, node_of_state[j]);
      for (int j = 0; j < nm; ++j) rs.y12(i, j) = y(ni, node_of_massless[j]);
      rs.b1.row(i) = yb.row(ni);
    }
    for (int i = 0; i < nm; ++i) {
      const int ni = node_of_massless[i];
      for (int j = 0; j < ns; ++j) rs.y21(i, j) = y(ni, node_of_state[j]);
      for (int j = 0; j < nm; ++j) rs.y22(i, j) = y(ni, node_of_massless[j]);
      rs.b2.row(i) = yb.row(ni);
    }
    // Loss injection: states take their own loss; massless nodes' losses pass through Y22^-1.
    rs.sel_x.setZero(ns, nn);
    rs.sel_z.setZero(nm, nn);
    for (int i = 0; i < ns; ++i) rs.sel_x(i, node_of_state[i]) = 1.0;
    for (int i = 0; i < nm; ++i) rs.sel_z(i, node_of_massless[i]) = 1.0;
    if (nm > 0) {
      Eigen::FullPivLU<Eigen::MatrixXd> lu(rs.y22);
      if (!lu.isInvertible()) return false;
      const Eigen::MatrixXd inv = lu.inverse();
      r.m_z = -inv * rs.y21;
      r.m_zb = -inv * rs.b2;
      r.g_z = -inv * rs.sel_z;
      r.a_red = rs.y11 + rs.y12 * r.m_z;
      r.b_b = rs.b1 + rs.y12 * r.m_zb;
      r.g = rs.sel_x + rs.y12 * r.g_z;
    } else {
      r.m_z.resize(0, ns);
      r.m_zb.resize(0, 2);
      r.g_z.resize(0, nn);
      r.a_red = rs.y11;
      r.b_b = rs.b1;
      r.g = rs.sel_x;
    }
    return true;
  }

  const Reduced& Current() const {
    if (!resistances_vary) return cached;
    if (!Reduce(scratch)) {
      throw std::domain_error(
          fmt::format("{}: the massless sub-network is singular at this operating point", source));
    }
    return scratch;
  }

  /// The reference temperature of loss `t`'s temperature coefficient: its own, or a boundary's.
  double Reference_degC(const LossTerm& t) const {
    return t.reference == 0 ? t.reference_degC : Boundary(t.reference);
  }

  /// Losses as p0 + D x (eqs. 1-8 with the copper law; eqs. 12-16), into the members p0, d.
  void LossModel() const {
    p0.setZero(N());
    d.setZero(N(), n());
    for (const LossTerm& t : losses) {
      const double p = t.power_W.Eval();
      double scale0 = 1.0;
      if (t.alpha_per_K != 0.0) {
        scale0 = 1.0 - t.alpha_per_K * Reference_degC(t);
      }
      for (const auto& [node, share] : t.shares) {
        p0(node) += share * p * scale0;
        if (t.alpha_per_K != 0.0) {
          const double w =
              share * p * t.alpha_per_K / static_cast<double>(t.temperature_states.size());
          for (int s : t.temperature_states) d(node, s) += w;
        }
      }
    }
  }

  /// Reads a model file into this Impl, one step per part of the file.
  class Parser;
};

ThermalModel::ThermalModel(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
ThermalModel::ThermalModel(ThermalModel&&) noexcept = default;
ThermalModel& ThermalModel::operator=(ThermalModel&&) noexcept = default;
ThermalModel::~ThermalModel() = default;

namespace {

void CheckKeys(const toml::table& t, std::initializer_list<const char*> allowed,
               const std::string& what, const std::string& source) {
  for (const auto& [k, v] : t) {
    bool ok = false;
    for (const char* a : allowed) ok = ok || k.str() == a;
    if (!ok) {
      throw ThermalModelError(
          fmt::format("{}: {}: unknown key '{}'", Where(source, LineOf(v)), what, k.str()));
    }
  }
}

/// `[operating_range]`: speed_rpm > 0, iq_A = 1 to 8 finite currents, scale_current_A > 0
/// (default: the largest |iq_A|).
ThermalOperatingRange ParseOperatingRange(const toml::node& n, const std::string& source) {
  const toml::table* t = n.as_table();
  auto fail = [&](const toml::node& at, const std::string& what) {
    throw ThermalModelError(
        fmt::format("{}: [operating_range]: {}", Where(source, LineOf(at)), what));
  };
  if (!t) fail(n, "must be a table");
  CheckKeys(*t, {"speed_rpm", "iq_A", "scale_current_A"}, "[operating_range]", source);
  ThermalOperatingRange r;
  const auto speed = (*t)["speed_rpm"].value<double>();
  if (!speed || !(*speed > 0.0) || !std::isfinite(*speed))
    fail(n, "speed_rpm must be a positive number");
  r.speed_rpm = *speed;
  const toml::array* iq = (*t)["iq_A"].as_array();
  if (!iq || iq->empty() || iq->size() > 8) fail(n, "iq_A must be an array of 1 to 8 currents");
  for (const auto& v : *iq) {
    const auto a = v.value<double>();
    if (!a || !std::isfinite(*a)) fail(v, "iq_A must hold finite numbers");
    r.iq_A.push_back(*a);
    r.scale_current_A = std::max(r.scale_current_A, std::abs(*a));
  }
  if (const toml::node* sc = t->get("scale_current_A")) {
    const auto a = sc->value<double>();
    if (!a || !(*a > 0.0) || !std::isfinite(*a))
      fail(*sc, "scale_current_A must be a positive number");
    r.scale_current_A = *a;
  }
  if (!(r.scale_current_A > 0.0))
    fail(n, "iq_A must hold a non-zero current (or give scale_current_A)");
  return r;
}

}  // namespace

/// The steps of ThermalModel::Parse, run in the order Parse() lists them; each throws
/// ThermalModelError naming the file and line (Impl::Fail).
class ThermalModel::Impl::Parser {
 public:
  Parser(Impl& m, const toml::table& root, const ThermalModelFiles& files)
      : m_(m), root_(root), files_(files) {}

  void Parse() {
    CheckKeys(
        root_,
        {"model", "parameters", "operating_range", "table", "quantity", "node", "edge", "loss"},
        "top level", m_.source);
    ParseHeader();
    ParseNodes();
    ReserveBuiltInNames();
    ParseTables();
    ParseQuantities();
    ParseEdges();
    CheckConnected();
    ParseLosses();
    SetWindingWeights();
    CheckMasslessGroups();
    SetRestPowers();
    m_.p0.setZero(m_.N());
    m_.d.setZero(m_.N(), m_.n());
  }

 private:
  Impl& m_;
  const toml::table& root_;
  const ThermalModelFiles& files_;
  std::map<std::string, int> index_;         ///< node index by name
  std::set<std::string> names_taken_;        ///< names an expression can read
  std::vector<std::vector<int>> adjacency_;  ///< node-to-node edges
  std::vector<bool> touches_boundary_;       ///< per node: an edge to ambient or coolant

  /// [model], [parameters], [operating_range].
  void ParseHeader() {
    if (const toml::table* model = root_["model"].as_table()) {
      CheckKeys(*model, {"name", "description", "source"}, "[model]", m_.source);
      m_.name = (*model)["name"].value_or(std::string{});
    }
    if (m_.name.empty()) m_.name = m_.source;
    if (const toml::node* params = root_.get("parameters")) {
      const toml::table* pt = params->as_table();
      if (!pt) m_.Fail(LineOf(*params), "[parameters] must be a table of numbers");
      for (const auto& [k, v] : *pt) {
        auto val = v.value<double>();
        if (!val || !std::isfinite(*val)) {
          m_.Fail(LineOf(v), fmt::format("parameter '{}' must be a finite number", k.str()));
        }
        m_.parameters[std::string(k.str())] = *val;
      }
    }
    if (const toml::node* range = root_.get("operating_range")) {
      m_.operating_range = ParseOperatingRange(*range, m_.source);
    }
  }

  /// [[node]]: names and heat capacities; then which nodes are states and which massless.
  void ParseNodes() {
    const toml::array* node_list = root_["node"].as_array();
    if (!node_list || node_list->empty()) m_.Fail(1, "no [[node]] tables");
    std::vector<double> caps;
    for (const toml::node& nv : *node_list) caps.push_back(ParseNode(nv));
    NumberStates(caps);
  }

  /// One [[node]]; returns its capacity (0 for massless).
  double ParseNode(const toml::node& nv) {
    const toml::table* nt = nv.as_table();
    if (!nt) m_.Fail(LineOf(nv), "[[node]] entries must be tables");
    const int line = LineOf(nv);
    CheckKeys(*nt, {"name", "capacity_J_per_K", "description"}, "[[node]]", m_.source);
    auto node_name = (*nt)["name"].value<std::string>();
    if (!node_name || node_name->empty()) m_.Fail(line, "[[node]] without a name");
    if (*node_name == "ambient" || *node_name == "coolant") {
      m_.Fail(line, fmt::format("node '{}': the name is reserved for a boundary", *node_name));
    }
    if (index_.count(*node_name))
      m_.Fail(line, fmt::format("node '{}' is declared twice", *node_name));
    const toml::node* cap = nt->get("capacity_J_per_K");
    if (!cap)
      m_.Fail(line,
              fmt::format("node '{}': missing capacity_J_per_K (0 for massless)", *node_name));
    const double c = m_.Compile(*cap, "capacity_J_per_K", false).value;
    if (c < 0.0) {
      m_.Fail(LineOf(*cap),
              fmt::format("node '{}': negative capacity_J_per_K ({})", *node_name, c));
    }
    index_[*node_name] = static_cast<int>(m_.nodes.size());
    m_.nodes.push_back({*node_name, c == 0.0, line});
    return c;
  }

  /// State and massless numbering of the nodes, capacities of the states.
  void NumberStates(const std::vector<double>& caps) {
    Impl& m = m_;
    for (int i = 0; i < m.N(); ++i) {
      if (m.nodes[i].massless) {
        m.massless_of_node.push_back(m.nz());
        m.state_of_node.push_back(-1);
        m.node_of_massless.push_back(i);
      } else {
        m.state_of_node.push_back(m.n());
        m.massless_of_node.push_back(-1);
        m.node_of_state.push_back(i);
        m.state_names.push_back(m.nodes[i].name);
      }
    }
    if (m.n() == 0) m.Fail(m.nodes.front().line, "every node is massless: the model has no state");
    m.capacity_J_per_K.resize(m.n());
    for (int s = 0; s < m.n(); ++s) m.capacity_J_per_K(s) = caps[m.node_of_state[s]];
    m.inv_capacity = m.capacity_J_per_K.cwiseInverse();
    m.vars->node_C.assign(static_cast<std::size_t>(m.n()), 25.0);
  }

  /// Parameters, node temperatures and inputs: names a table or quantity may not take.
  void ReserveBuiltInNames() {
    for (const auto& [k, v] : m_.parameters) names_taken_.insert(k);
    for (const auto& st : m_.state_names) names_taken_.insert(st + "_C");
    for (const char* v : {"speed_rpm", "speed_rad_per_s", "id_A", "iq_A", "is_A", "i2_A2",
                          "ambient_C", "coolant_C"}) {
      names_taken_.insert(v);
    }
  }

  /// A new name for an expression to read: an identifier, not taken yet.
  void TakeName(const std::string& what, const std::string& nm, int line) {
    static const std::string kFirst = "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ_";
    static const std::string kRest = kFirst + "0123456789";
    if (nm.empty() || kFirst.find(nm[0]) == std::string::npos ||
        nm.find_first_not_of(kRest) != std::string::npos) {
      m_.Fail(line,
              fmt::format("{} '{}': a name is letters, digits and '_', not starting with a digit",
                          what, nm));
    }
    if (!names_taken_.insert(nm).second) {
      m_.Fail(line, fmt::format(
                        "{} '{}': the name is already a parameter, input, node temperature, table "
                        "or quantity",
                        what, nm));
    }
  }

  /// [[table]]: loss maps and curves from CSV files named relative to the model file.
  void ParseTables() {
    const toml::node* tv = root_.get("table");
    if (!tv) return;
    const toml::array* ta = tv->as_array();
    if (!ta) m_.Fail(LineOf(*tv), "'table' must be an array of tables ([[table]])");
    for (const toml::node& e : *ta) m_.tables.push_back(ParseTable(e));
  }

  std::unique_ptr<Table> ParseTable(const toml::node& e) {
    const toml::table* tt = e.as_table();
    const int line = LineOf(e);
    if (!tt) m_.Fail(line, "[[table]] entries must be tables");
    CheckKeys(*tt, {"name", "file", "kind", "lookup", "description"}, "[[table]]", m_.source);
    auto t = std::make_unique<Table>();
    t->name = (*tt)["name"].value_or(std::string{});
    TakeName("table", t->name, line);
    const std::string kind = (*tt)["kind"].value_or(std::string{});
    if (kind != "map" && kind != "curve") {
      m_.Fail(line, fmt::format("table '{}': kind must be \"map\" (2-D over rows and columns) or "
                                "\"curve\" (1-D)",
                                t->name));
    }
    const std::string lookup = (*tt)["lookup"].value_or(std::string{});
    if (lookup != "linear" && lookup != "nearest") {
      m_.Fail(line,
              fmt::format("table '{}': lookup must be \"linear\" (interpolation) or \"nearest\" "
                          "(rounding to the grid)",
                          t->name));
    }
    t->linear = lookup == "linear";
    const std::string file = (*tt)["file"].value_or(std::string{});
    if (file.empty())
      m_.Fail(line, fmt::format("table '{}': missing file = \"<path relative to the model file>\"",
                                t->name));
    if (!files_.read) {
      m_.Fail(line,
              fmt::format("table '{}': this model names a file ({}) but no file reader was given "
                          "to the parser",
                          t->name, file));
    }
    const std::string path = JoinPath(files_.directory, file);
    try {
      ParseTableCsv(files_.read(path), path, kind == "map", *t);
    } catch (const std::exception& err) {
      m_.Fail(line, fmt::format("table '{}': {}", t->name, err.what()));
    }
    return t;
  }

  /// [[quantity]]: named expressions of the operating point, evaluated in file order.
  void ParseQuantities() {
    const toml::node* qv = root_.get("quantity");
    if (!qv) return;
    const toml::array* qa = qv->as_array();
    if (!qa) m_.Fail(LineOf(*qv), "'quantity' must be an array of tables ([[quantity]])");
    for (const toml::node& e : *qa) {
      const toml::table* qt = e.as_table();
      const int line = LineOf(e);
      if (!qt) m_.Fail(line, "[[quantity]] entries must be tables");
      CheckKeys(*qt, {"name", "value", "description"}, "[[quantity]]", m_.source);
      Impl::Quantity q;
      q.name = (*qt)["name"].value_or(std::string{});
      TakeName("quantity", q.name, line);
      const toml::node* val = qt->get("value");
      if (!val) m_.Fail(line, fmt::format("quantity '{}': missing value", q.name));
      q.value = m_.Compile(*val, fmt::format("quantity {}.value", q.name), true);
      if (q.value.Varies()) {
        m_.vars->quantity.push_back(q.value.value);
        q.slot = &m_.vars->quantity.back();
      }
      m_.quantities.push_back(std::move(q));
    }
  }

  /// An edge's end: a node index, kAmbient or kCoolant.
  int EndOf(const std::string& nm, int line, const std::string& label) const {
    if (nm == "ambient") return kAmbient;
    if (nm == "coolant") return kCoolant;
    auto it = index_.find(nm);
    if (it == index_.end()) m_.Fail(line, fmt::format("edge {}: unknown node '{}'", label, nm));
    return it->second;
  }

  /// [[edge]]: thermal resistances between nodes and boundaries.
  void ParseEdges() {
    const toml::array* edge_list = root_["edge"].as_array();
    if (!edge_list || edge_list->empty()) m_.Fail(1, "no [[edge]] tables");
    adjacency_.assign(static_cast<std::size_t>(m_.N()), {});
    touches_boundary_.assign(static_cast<std::size_t>(m_.N()), false);
    for (const toml::node& ev : *edge_list) m_.edges.push_back(ParseEdge(ev));
  }

  Edge ParseEdge(const toml::node& ev) {
    const toml::table* et = ev.as_table();
    const int line = LineOf(ev);
    if (!et) m_.Fail(line, "[[edge]] entries must be tables");
    CheckKeys(*et, {"between", "resistance_K_per_W", "name", "description"}, "[[edge]]", m_.source);
    const toml::array* between = (*et)["between"].as_array();
    if (!between || between->size() != 2 || !(*between)[0].is_string() ||
        !(*between)[1].is_string()) {
      m_.Fail(line,
              "[[edge]]: 'between' must name two nodes, e.g. between = [\"frame\", \"ambient\"]");
    }
    const std::string na = *(*between)[0].value<std::string>();
    const std::string nb = *(*between)[1].value<std::string>();
    const std::string label = (*et)["name"].value_or(fmt::format("{}-{}", na, nb));
    Edge e;
    e.a = EndOf(na, line, label);
    e.b = EndOf(nb, line, label);
    e.line = line;
    e.label = label;
    if (e.a < 0 && e.b < 0) m_.Fail(line, fmt::format("edge {} joins two boundaries", label));
    if (e.a == e.b) m_.Fail(line, fmt::format("edge {} joins node '{}' to itself", label, na));
    if (e.a < 0) std::swap(e.a, e.b);
    const toml::node* r = et->get("resistance_K_per_W");
    if (!r) m_.Fail(line, fmt::format("edge {}: missing resistance_K_per_W", label));
    e.resistance_K_per_W = m_.Compile(*r, "resistance_K_per_W", true);
    if (e.resistance_K_per_W.value == 0.0) {
      m_.Fail(LineOf(*r),
              fmt::format("edge {}: zero resistance (merge the two nodes instead)", label));
    }
    m_.resistances_vary = m_.resistances_vary || e.resistance_K_per_W.Varies();
    m_.uses_node_temperatures = m_.uses_node_temperatures || e.resistance_K_per_W.reads_nodes;
    if (e.b < 0) {
      touches_boundary_[e.a] = true;
      m_.uses_coolant = m_.uses_coolant || e.b == kCoolant;
    } else {
      adjacency_[e.a].push_back(e.b);
      adjacency_[e.b].push_back(e.a);
    }
    return e;
  }

  /// Every node has an edge and a path to a boundary.
  void CheckConnected() const {
    const Impl& m = m_;
    for (int i = 0; i < m.N(); ++i) {
      if (adjacency_[i].empty() && !touches_boundary_[i]) {
        m.Fail(m.nodes[i].line,
               fmt::format("node '{}' is not connected to any edge", m.nodes[i].name));
      }
    }
    std::vector<bool> reached(static_cast<std::size_t>(m.N()), false);
    std::vector<int> stack;
    for (int i = 0; i < m.N(); ++i) {
      if (touches_boundary_[i]) {
        reached[i] = true;
        stack.push_back(i);
      }
    }
    while (!stack.empty()) {
      const int i = stack.back();
      stack.pop_back();
      for (int j : adjacency_[i]) {
        if (!reached[j]) {
          reached[j] = true;
          stack.push_back(j);
        }
      }
    }
    for (int i = 0; i < m.N(); ++i) {
      if (!reached[i]) {
        m.Fail(m.nodes[i].line,
               fmt::format("node '{}' has no path to a boundary (ambient or coolant): its "
                           "temperature is undefined in steady state",
                           m.nodes[i].name));
      }
    }
  }

  /// [[loss]]: heat sources, their shares over the nodes and their temperature dependence.
  void ParseLosses() {
    const toml::node* lv = root_.get("loss");
    if (!lv) return;
    const toml::array* la = lv->as_array();
    if (!la) m_.Fail(LineOf(*lv), "'loss' must be an array of tables ([[loss]])");
    for (const toml::node& tv : *la) m_.losses.push_back(ParseLoss(tv));
  }

  LossTerm ParseLoss(const toml::node& tv) {
    const toml::table* tt = tv.as_table();
    const int line = LineOf(tv);
    if (!tt) m_.Fail(line, "[[loss]] entries must be tables");
    CheckKeys(*tt,
              {"name", "description", "power_W", "shares", "temperature_coefficient_per_K",
               "temperature_nodes", "reference", "reference_C"},
              "[[loss]]", m_.source);
    LossTerm t;
    t.line = line;
    t.name = (*tt)["name"].value_or(fmt::format("loss at line {}", line));
    const toml::node* p = tt->get("power_W");
    if (!p) m_.Fail(line, fmt::format("loss '{}': missing power_W", t.name));
    t.power_W = m_.Compile(*p, "power_W", true);
    m_.uses_node_temperatures = m_.uses_node_temperatures || t.power_W.reads_nodes;
    ParseShares(*tt, t);
    if (const toml::node* a = tt->get("temperature_coefficient_per_K")) {
      t.alpha_per_K = m_.Compile(*a, "temperature_coefficient_per_K", false).value;
    }
    if (t.alpha_per_K != 0.0) ParseLossTemperature(*tt, t);
    return t;
  }

  /// shares = { node = fraction, ... } of a loss.
  void ParseShares(const toml::table& tt, LossTerm& t) {
    const toml::table* shares = tt["shares"].as_table();
    if (!shares || shares->empty()) {
      m_.Fail(t.line,
              fmt::format("loss '{}': missing shares = {{ node = fraction, ... }}", t.name));
    }
    for (const auto& [k, v] : *shares) {
      auto it = index_.find(std::string(k.str()));
      if (it == index_.end()) {
        m_.Fail(LineOf(v), fmt::format("loss '{}': share for unknown node '{}'", t.name, k.str()));
      }
      const double s = m_.Compile(v, fmt::format("shares.{}", k.str()), false).value;
      if (s < 0.0) {
        m_.Fail(LineOf(v), fmt::format("loss '{}': negative share for node '{}'", t.name, k.str()));
      }
      t.shares.emplace_back(it->second, s);
    }
  }

  /// The temperature dependence of a loss: its nodes and its reference temperature.
  void ParseLossTemperature(const toml::table& tt, LossTerm& t) {
    const toml::array* tn = tt["temperature_nodes"].as_array();
    if (!tn || tn->empty()) {
      m_.Fail(t.line, fmt::format("loss '{}': temperature_coefficient_per_K needs "
                                  "temperature_nodes",
                                  t.name));
    }
    for (const toml::node& x : *tn) {
      auto s = x.value<std::string>();
      auto it = s ? index_.find(*s) : index_.end();
      if (it == index_.end() || m_.state_of_node[it->second] < 0) {
        m_.Fail(LineOf(x), fmt::format("loss '{}': temperature node '{}' is not a node with "
                                       "heat capacity",
                                       t.name, s.value_or("?")));
      }
      t.temperature_states.push_back(m_.state_of_node[it->second]);
    }
    const bool has_ref = tt.contains("reference");
    const bool has_ref_c = tt.contains("reference_C");
    if (has_ref == has_ref_c) {
      m_.Fail(t.line, fmt::format("loss '{}': give exactly one of reference = \"ambient\"|"
                                  "\"coolant\" or reference_C = <degC>",
                                  t.name));
    }
    if (!has_ref) {
      t.reference_degC = m_.Compile(*tt.get("reference_C"), "reference_C", false).value;
      return;
    }
    const std::string r = tt["reference"].value_or(std::string{});
    if (r == "ambient") {
      t.reference = kAmbient;
    } else if (r == "coolant") {
      t.reference = kCoolant;
      m_.uses_coolant = true;
    } else {
      m_.Fail(LineOf(*tt.get("reference")),
              fmt::format("loss '{}': reference must be \"ambient\" or \"coolant\"", t.name));
    }
  }

  /// Winding weights: the temperature nodes of the temperature-dependent losses, equally.
  void SetWindingWeights() {
    m_.winding_weights = Eigen::VectorXd::Zero(m_.n());
    std::set<int> states;
    for (const LossTerm& t : m_.losses) {
      if (t.alpha_per_K > 0.0)
        states.insert(t.temperature_states.begin(), t.temperature_states.end());
    }
    for (int s : states) m_.winding_weights(s) = 1.0 / static_cast<double>(states.size());
  }

  /// The connected groups of massless nodes, as group index per node (-1: not massless).
  std::vector<int> MasslessGroups(int& groups) const {
    std::vector<int> group(static_cast<std::size_t>(m_.N()), -1);
    groups = 0;
    for (int start : m_.node_of_massless) {
      if (group[start] >= 0) continue;
      std::vector<int> stack{start};
      group[start] = groups;
      while (!stack.empty()) {
        const int i = stack.back();
        stack.pop_back();
        for (int j : adjacency_[i]) {
          if (m_.nodes[j].massless && group[j] < 0) {
            group[j] = groups;
            stack.push_back(j);
          }
        }
      }
      ++groups;
    }
    return group;
  }

  /// Each connected group of massless nodes must have an invertible Y22 (eq. S25), at the
  /// operating point of zero inputs; then the reduction of the whole network must succeed.
  void CheckMasslessGroups() {
    int groups = 0;
    const std::vector<int> group = MasslessGroups(groups);
    m_.SetInputs(ThermalInputs{});
    for (int gidx = 0; gidx < groups; ++gidx) {
      std::vector<int> members;
      for (int i = 0; i < m_.N(); ++i) {
        if (group[i] == gidx) members.push_back(i);
      }
      CheckMasslessGroup(members);
    }
    if (!m_.Reduce(m_.cached)) m_.Fail(1, "the massless sub-network is singular");
  }

  /// Each loss's power at rest (speed and currents zero) where it is a constant, and each loss's
  /// heat rate per watt on the states (C^-1 G times its shares) where the network is fixed.
  void SetRestPowers() {
    m_.SetInputs(ThermalInputs{});
    const int n = m_.n();
    m_.loss_rate_per_W.setZero(n, static_cast<Eigen::Index>(m_.losses.size()));
    for (std::size_t k = 0; k < m_.losses.size(); ++k) {
      LossTerm& t = m_.losses[k];
      if (!t.power_W.reads_nodes && !t.power_W.reads_boundaries) {
        t.power_at_rest_W = t.power_W.Eval();
      }
      for (const auto& [node, share] : t.shares) {
        m_.loss_rate_per_W.col(static_cast<Eigen::Index>(k)) += share * m_.cached.g.col(node);
      }
    }
    m_.loss_rate_per_W.array().colwise() *= m_.inv_capacity.array();
    m_.power_W.assign(m_.losses.size(), 0.0);
  }

  void CheckMasslessGroup(const std::vector<int>& members) const {
    const int k = static_cast<int>(members.size());
    Eigen::MatrixXd y = Eigen::MatrixXd::Zero(k, k);
    for (const Edge& e : m_.edges) {
      const double g = 1.0 / e.resistance_K_per_W.Eval();
      for (int r = 0; r < k; ++r) {
        const int i = members[r];
        if (e.a != i && e.b != i) continue;
        y(r, r) -= g;
        const int other = e.a == i ? e.b : e.a;
        for (int c = 0; c < k; ++c) {
          if (members[c] == other) y(r, c) += g;
        }
      }
    }
    Eigen::FullPivLU<Eigen::MatrixXd> lu(y);
    lu.setThreshold(1e-10);
    if (lu.isInvertible()) return;
    std::string names;
    for (int i : members)
      names += fmt::format("{}'{}' (line {})", names.empty() ? "" : ", ", m_.nodes[i].name,
                           m_.nodes[i].line);
    m_.Fail(m_.nodes[members.front()].line,
            fmt::format("massless nodes {} form a singular sub-network: Y22 of eq. S25 "
                        "cannot be inverted",
                        names));
  }
};

ThermalModel ThermalModel::Parse(std::string_view toml_text, const std::string& source,
                                 const ThermalModelFiles& files) {
  auto impl = std::make_unique<Impl>();
  impl->source = source;
  toml::table root;
  try {
    root = toml::parse(toml_text, source);
  } catch (const toml::parse_error& e) {
    throw ThermalModelError(fmt::format(
        "{}: {}", Where(source, static_cast<int>(e.source().begin.line)), e.description()));
  }
  Impl::Parser(*impl, root, files).Parse();
  return ThermalModel(std::move(impl));
}

const std::string& ThermalModel::Name() const { return impl_->name; }
const ThermalOperatingRange* ThermalModel::OperatingRange() const {
  return impl_->operating_range ? &*impl_->operating_range : nullptr;
}
const std::vector<ThermalNodeInfo>& ThermalModel::Nodes() const { return impl_->nodes; }
int ThermalModel::StateCount() const { return impl_->n(); }
const std::vector<std::string>& ThermalModel::StateNames() const { return impl_->state_names; }
int ThermalModel::StateIndex(std::string_view node) const {
  for (int s = 0; s < impl_->n(); ++s) {
    if (impl_->state_names[s] == node) return s;
  }
  return -1;
}
const Eigen::VectorXd& ThermalModel::Capacities_J_per_K() const { return impl_->capacity_J_per_K; }
bool ThermalModel::UsesCoolant() const { return impl_->uses_coolant; }
bool ThermalModel::ResistancesVary() const { return impl_->resistances_vary; }
const Eigen::VectorXd& ThermalModel::WindingWeights() const { return impl_->winding_weights; }

bool ThermalModel::UsesNodeTemperatures() const { return impl_->uses_node_temperatures; }

bool ThermalModel::AcceptsInputs(const ThermalInputs& in) const {
  return std::isfinite(in.speed_rpm) && std::isfinite(in.id_A) && std::isfinite(in.iq_A) &&
         std::isfinite(in.ambient_degC) && (!UsesCoolant() || std::isfinite(in.coolant_degC));
}

void ThermalModel::Linearise(const ThermalInputs& in, const Eigen::VectorXd& x_degC,
                             ThermalLinearModel& out) const {
  impl_->SetTemperatures(x_degC);
  Linearise(in, out);
}

void ThermalModel::Linearise(const ThermalInputs& in, const Eigen::VectorXd& x_degC,
                             ThermalLinearModel& out, ThermalLossRates& rates) const {
  Linearise(in, x_degC, out);
  const Impl& m = *impl_;
  ThermalInputs still = in;
  still.speed_rpm = 0.0;
  ThermalInputs rest = still;
  rest.id_A = rest.iq_A = 0.0;
  if (m.resistances_vary) {
    // The network itself may change with the speed or the currents: difference the three
    // linearisations, (a x + f) at one set of inputs minus another.
    Linearise(still, x_degC, m.still_scratch);
    Linearise(rest, x_degC, m.rest_scratch);
    const auto difference = [&x_degC](const ThermalLinearModel& with,
                                      const ThermalLinearModel& without, Eigen::VectorXd& rate) {
      rate.noalias() = with.a_per_s * x_degC;
      rate += with.f_K_per_s;
      rate.noalias() -= without.a_per_s * x_degC;
      rate -= without.f_K_per_s;
    };
    difference(m.still_scratch, m.rest_scratch, rates.current_K_per_s);
    difference(out, m.still_scratch, rates.speed_K_per_s);
    return;
  }
  rates.current_K_per_s.setZero(m.n());
  rates.speed_K_per_s.setZero(m.n());
  // A loss's value changes only with what it reads; at rest it may be a constant.
  const ThermalInputs* set = &in;  // where the expressions' inputs are now
  const auto power_at = [&m, &set](const ThermalInputs& where, const LossTerm& t) {
    if (set != &where) m.SetInputs(where);
    set = &where;
    return t.power_W.Eval();
  };
  for (std::size_t k = 0; k < m.losses.size(); ++k) {
    const LossTerm& t = m.losses[k];
    const Expression& e = t.power_W;
    const double p_in = m.power_W[k];
    double p_still = p_in;
    if (e.reads_speed) {
      p_still = t.power_at_rest_W && !e.reads_currents ? *t.power_at_rest_W : power_at(still, t);
    }
    double p_rest = p_still;
    if (e.reads_currents) p_rest = t.power_at_rest_W ? *t.power_at_rest_W : power_at(rest, t);
    // The loss's temperature factor 1 + alpha (T - T_ref) at x, as Linearise puts it in a and f.
    double factor = 1.0;
    if (t.alpha_per_K != 0.0) {
      const double ref = m.Reference_degC(t);
      double mean = 0.0;
      for (int st : t.temperature_states) mean += x_degC(st);
      factor += t.alpha_per_K * (mean / static_cast<double>(t.temperature_states.size()) - ref);
    }
    const auto col = m.loss_rate_per_W.col(static_cast<Eigen::Index>(k));
    rates.current_K_per_s += col * ((p_still - p_rest) * factor);
    rates.speed_K_per_s += col * ((p_in - p_still) * factor);
  }
}

void ThermalModel::Linearise(const ThermalInputs& in, ThermalLinearModel& out) const {
  const Impl& m = *impl_;
  m.SetInputs(in);
  const bool same = in.speed_rpm == m.last_in.speed_rpm && in.id_A == m.last_in.id_A &&
                    in.iq_A == m.last_in.iq_A && in.ambient_degC == m.last_in.ambient_degC &&
                    (!m.uses_coolant || in.coolant_degC == m.last_in.coolant_degC);
  if (m.last_valid && same) {
    out.a_per_s = m.last_lin.a_per_s;
    out.f_K_per_s = m.last_lin.f_K_per_s;
    return;
  }
  const Reduced& r = m.Current();
  const Eigen::Vector2d tb(m.vars->ambient_C, m.vars->coolant_C);
  out.a_per_s.resize(m.n(), m.n());
  out.f_K_per_s.resize(m.n());
  out.a_per_s = r.a_red;
  out.f_K_per_s.noalias() = r.b_b * tb;
  // A + G D and B_b T_b + G p0, one loss term at a time: each term touches only the columns of
  // G of its share nodes and the columns of A of its temperature nodes (cheaper than G * D).
  for (std::size_t k = 0; k < m.losses.size(); ++k) {
    const LossTerm& t = m.losses[k];
    const double p = t.power_W.Eval();
    m.power_W[k] = p;
    double scale0 = 1.0;
    if (t.alpha_per_K != 0.0) {
      scale0 = 1.0 - t.alpha_per_K * m.Reference_degC(t);
    }
    for (const auto& [node, share] : t.shares) {
      out.f_K_per_s += r.g.col(node) * (share * p * scale0);
      if (t.alpha_per_K != 0.0) {
        const double w =
            share * p * t.alpha_per_K / static_cast<double>(t.temperature_states.size());
        for (int st : t.temperature_states) out.a_per_s.col(st) += r.g.col(node) * w;
      }
    }
  }
  out.a_per_s.array().colwise() *= m.inv_capacity.array();
  out.f_K_per_s.array() *= m.inv_capacity.array();
  m.last_valid = !m.resistances_vary && !m.uses_node_temperatures;
  if (m.last_valid) {
    m.last_lin.a_per_s = out.a_per_s;
    m.last_lin.f_K_per_s = out.f_K_per_s;
    m.last_in = in;
  }
}

Eigen::VectorXd ThermalModel::NodeLosses_W(const ThermalInputs& in,
                                           const Eigen::VectorXd& x_degC) const {
  const Impl& m = *impl_;
  m.SetTemperatures(x_degC);
  m.SetInputs(in);
  m.LossModel();
  return m.p0 + m.d * x_degC;
}

Eigen::VectorXd ThermalModel::AllTemperatures_degC(const ThermalInputs& in,
                                                   const Eigen::VectorXd& x_degC) const {
  const Impl& m = *impl_;
  m.SetTemperatures(x_degC);
  m.SetInputs(in);
  const Reduced& r = m.Current();
  m.LossModel();
  const Eigen::Vector2d tb(m.vars->ambient_C, m.vars->coolant_C);
  const Eigen::VectorXd p = m.p0 + m.d * x_degC;
  Eigen::VectorXd all(m.N());
  for (int s = 0; s < m.n(); ++s) all(m.node_of_state[s]) = x_degC(s);
  if (m.nz() > 0) {
    const Eigen::VectorXd z = r.m_z * x_degC + r.m_zb * tb + r.g_z * p;
    for (int k = 0; k < m.nz(); ++k) all(m.node_of_massless[k]) = z(k);
  }
  return all;
}

Eigen::MatrixXd ThermalModel::AllTemperatureJacobian(const ThermalInputs& in) const {
  const Impl& m = *impl_;
  m.SetInputs(in);
  const Reduced& r = m.Current();
  m.LossModel();
  Eigen::MatrixXd j = Eigen::MatrixXd::Zero(m.N(), m.n());
  for (int s = 0; s < m.n(); ++s) j(m.node_of_state[s], s) = 1.0;
  if (m.nz() > 0) {
    const Eigen::MatrixXd jz = r.m_z + r.g_z * m.d;
    for (int k = 0; k < m.nz(); ++k) j.row(m.node_of_massless[k]) = jz.row(k);
  }
  return j;
}

Eigen::VectorXd ThermalModel::SteadyState_degC(const ThermalInputs& in) const {
  ThermalLinearModel lin;
  Linearise(in, lin);
  Eigen::FullPivLU<Eigen::MatrixXd> lu(lin.a_per_s);
  if (!lu.isInvertible())
    throw std::domain_error("thermal model: singular system, no steady state");
  return lu.solve(-lin.f_K_per_s);
}

}  // namespace pumptherm::estimators
