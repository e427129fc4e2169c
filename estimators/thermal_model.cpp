#include "estimators/thermal_model.hpp"

#include <fmt/core.h>
#include <fmt/format.h>

#include <Eigen/LU>
#include <cmath>
#include <map>
#include <muParser.h>
#include <optional>
#include <set>
#include <toml++/toml.h>

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
};

/// A number, or a muParser expression of the parameters and (where allowed) the inputs.
struct Expression {
  double value = 0.0;                  ///< the value when constant
  std::unique_ptr<mu::Parser> parser;  ///< set only when the expression reads an input
  std::string text;

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
  bool uses_coolant = false;
  bool resistances_vary = false;
  Eigen::VectorXd winding_weights;
  Reduced cached;  ///< valid when !resistances_vary
  // Scratch for Linearise (mutable: Linearise is logically const).
  mutable Reduced scratch;
  mutable Eigen::VectorXd p0;
  mutable Eigen::MatrixXd d;

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
        if (inputs_allowed) {
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
        if (!p->GetUsedVar().empty()) e.parser = std::move(p);
      } catch (const mu::Parser::exception_type& err) {
        Fail(LineOf(n), fmt::format("key '{}': expression \"{}\": {}{}", key, *s, err.GetMsg(),
                                    inputs_allowed ? "" : " (only parameters may be used here)"));
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
  }

  double Boundary(int code) const { return code == kAmbient ? vars->ambient_C : vars->coolant_C; }

  /// Assembles KCL and reduces it (eq. S25) at the current variable values.
  bool Reduce(Reduced& r) const {
    const int nn = N(), ns = n(), nm = nz();
    Eigen::MatrixXd y = Eigen::MatrixXd::Zero(nn, nn);
    Eigen::MatrixXd yb = Eigen::MatrixXd::Zero(nn, 2);
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
    Eigen::MatrixXd y11(ns, ns), y12(ns, nm), y21(nm, ns), y22(nm, nm), b1(ns, 2), b2(nm, 2);
    for (int i = 0; i < ns; ++i) {
      const int ni = node_of_state[i];
      for (int j = 0; j < ns; ++j) y11(i, j) = y(ni, node_of_state[j]);
      for (int j = 0; j < nm; ++j) y12(i, j) = y(ni, node_of_massless[j]);
      b1.row(i) = yb.row(ni);
    }
    for (int i = 0; i < nm; ++i) {
      const int ni = node_of_massless[i];
      for (int j = 0; j < ns; ++j) y21(i, j) = y(ni, node_of_state[j]);
      for (int j = 0; j < nm; ++j) y22(i, j) = y(ni, node_of_massless[j]);
      b2.row(i) = yb.row(ni);
    }
    // Loss injection: states take their own loss; massless nodes' losses pass through Y22^-1.
    Eigen::MatrixXd sel_x = Eigen::MatrixXd::Zero(ns, nn), sel_z = Eigen::MatrixXd::Zero(nm, nn);
    for (int i = 0; i < ns; ++i) sel_x(i, node_of_state[i]) = 1.0;
    for (int i = 0; i < nm; ++i) sel_z(i, node_of_massless[i]) = 1.0;
    if (nm > 0) {
      Eigen::FullPivLU<Eigen::MatrixXd> lu(y22);
      if (!lu.isInvertible()) return false;
      const Eigen::MatrixXd inv = lu.inverse();
      r.m_z = -inv * y21;
      r.m_zb = -inv * b2;
      r.g_z = -inv * sel_z;
      r.a_red = y11 + y12 * r.m_z;
      r.b_b = b1 + y12 * r.m_zb;
      r.g = sel_x + y12 * r.g_z;
    } else {
      r.m_z.resize(0, ns);
      r.m_zb.resize(0, 2);
      r.g_z.resize(0, nn);
      r.a_red = y11;
      r.b_b = b1;
      r.g = sel_x;
    }
    return true;
  }

  const Reduced& Current() const {
    if (!resistances_vary) return cached;
    if (!Reduce(scratch)) {
      throw std::domain_error(fmt::format(
          "{}: the massless sub-network is singular at this operating point", source));
    }
    return scratch;
  }

  /// Losses as p0 + D x (eqs. 1-8 with the copper law; eqs. 12-16), into the members p0, d.
  void LossModel() const {
    p0.setZero(N());
    d.setZero(N(), n());
    for (const LossTerm& t : losses) {
      const double p = t.power_W.Eval();
      double scale0 = 1.0;
      if (t.alpha_per_K != 0.0) {
        const double ref = t.reference == 0 ? t.reference_degC : Boundary(t.reference);
        scale0 = 1.0 - t.alpha_per_K * ref;
      }
      for (const auto& [node, share] : t.shares) {
        p0(node) += share * p * scale0;
        if (t.alpha_per_K != 0.0) {
          const double w = share * p * t.alpha_per_K /
                           static_cast<double>(t.temperature_states.size());
          for (int s : t.temperature_states) d(node, s) += w;
        }
      }
    }
  }
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
      throw ThermalModelError(fmt::format("{}: {}: unknown key '{}'", Where(source, LineOf(v)),
                                          what, k.str()));
    }
  }
}

}  // namespace

ThermalModel ThermalModel::Parse(std::string_view toml_text, const std::string& source) {
  auto impl = std::make_unique<Impl>();
  Impl& m = *impl;
  m.source = source;
  toml::table root;
  try {
    root = toml::parse(toml_text, source);
  } catch (const toml::parse_error& e) {
    throw ThermalModelError(fmt::format("{}: {}", Where(source, static_cast<int>(e.source().begin.line)),
                                        e.description()));
  }
  CheckKeys(root, {"model", "parameters", "node", "edge", "loss"}, "top level", source);

  if (const toml::table* model = root["model"].as_table()) {
    CheckKeys(*model, {"name", "description", "source"}, "[model]", source);
    m.name = (*model)["name"].value_or(std::string{});
  }
  if (m.name.empty()) m.name = source;

  if (const toml::node* params = root.get("parameters")) {
    const toml::table* pt = params->as_table();
    if (!pt) m.Fail(LineOf(*params), "[parameters] must be a table of numbers");
    for (const auto& [k, v] : *pt) {
      auto val = v.value<double>();
      if (!val || !std::isfinite(*val)) {
        m.Fail(LineOf(v), fmt::format("parameter '{}' must be a finite number", k.str()));
      }
      m.parameters[std::string(k.str())] = *val;
    }
  }

  // Nodes.
  const toml::array* nodes = root["node"].as_array();
  if (!nodes || nodes->empty()) m.Fail(1, "no [[node]] tables");
  std::map<std::string, int> index;
  std::vector<double> caps;
  for (const toml::node& nv : *nodes) {
    const toml::table* nt = nv.as_table();
    if (!nt) m.Fail(LineOf(nv), "[[node]] entries must be tables");
    const int line = LineOf(nv);
    CheckKeys(*nt, {"name", "capacity_J_per_K", "description"}, "[[node]]", source);
    auto name = (*nt)["name"].value<std::string>();
    if (!name || name->empty()) m.Fail(line, "[[node]] without a name");
    if (*name == "ambient" || *name == "coolant") {
      m.Fail(line, fmt::format("node '{}': the name is reserved for a boundary", *name));
    }
    if (index.count(*name)) m.Fail(line, fmt::format("node '{}' is declared twice", *name));
    const toml::node* cap = nt->get("capacity_J_per_K");
    if (!cap) m.Fail(line, fmt::format("node '{}': missing capacity_J_per_K (0 for massless)", *name));
    const double c = m.Compile(*cap, "capacity_J_per_K", false).value;
    if (c < 0.0) {
      m.Fail(LineOf(*cap), fmt::format("node '{}': negative capacity_J_per_K ({})", *name, c));
    }
    index[*name] = static_cast<int>(m.nodes.size());
    m.nodes.push_back({*name, c == 0.0, line});
    caps.push_back(c);
  }
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

  auto end_of = [&](const std::string& nm, int line, const std::string& label) {
    if (nm == "ambient") return kAmbient;
    if (nm == "coolant") return kCoolant;
    auto it = index.find(nm);
    if (it == index.end()) m.Fail(line, fmt::format("edge {}: unknown node '{}'", label, nm));
    return it->second;
  };

  // Edges.
  const toml::array* edges = root["edge"].as_array();
  if (!edges || edges->empty()) m.Fail(1, "no [[edge]] tables");
  std::vector<std::vector<int>> adjacency(static_cast<std::size_t>(m.N()));
  std::vector<bool> touches_boundary(static_cast<std::size_t>(m.N()), false);
  for (const toml::node& ev : *edges) {
    const toml::table* et = ev.as_table();
    const int line = LineOf(ev);
    if (!et) m.Fail(line, "[[edge]] entries must be tables");
    CheckKeys(*et, {"between", "resistance_K_per_W", "name", "description"}, "[[edge]]", source);
    const toml::array* between = (*et)["between"].as_array();
    if (!between || between->size() != 2 || !(*between)[0].is_string() ||
        !(*between)[1].is_string()) {
      m.Fail(line, "[[edge]]: 'between' must name two nodes, e.g. between = [\"frame\", \"ambient\"]");
    }
    const std::string na = *(*between)[0].value<std::string>();
    const std::string nb = *(*between)[1].value<std::string>();
    const std::string label = (*et)["name"].value_or(fmt::format("{}-{}", na, nb));
    Edge e;
    e.a = end_of(na, line, label);
    e.b = end_of(nb, line, label);
    e.line = line;
    e.label = label;
    if (e.a < 0 && e.b < 0) m.Fail(line, fmt::format("edge {} joins two boundaries", label));
    if (e.a == e.b) m.Fail(line, fmt::format("edge {} joins node '{}' to itself", label, na));
    if (e.a < 0) std::swap(e.a, e.b);
    const toml::node* r = et->get("resistance_K_per_W");
    if (!r) m.Fail(line, fmt::format("edge {}: missing resistance_K_per_W", label));
    e.resistance_K_per_W = m.Compile(*r, "resistance_K_per_W", true);
    if (e.resistance_K_per_W.value == 0.0) {
      m.Fail(LineOf(*r), fmt::format("edge {}: zero resistance (merge the two nodes instead)", label));
    }
    m.resistances_vary = m.resistances_vary || e.resistance_K_per_W.Varies();
    if (e.b < 0) {
      touches_boundary[e.a] = true;
      m.uses_coolant = m.uses_coolant || e.b == kCoolant;
    } else {
      adjacency[e.a].push_back(e.b);
      adjacency[e.b].push_back(e.a);
    }
    m.edges.push_back(std::move(e));
  }

  // Connectivity: every node has an edge and a path to a boundary.
  for (int i = 0; i < m.N(); ++i) {
    if (adjacency[i].empty() && !touches_boundary[i]) {
      m.Fail(m.nodes[i].line, fmt::format("node '{}' is not connected to any edge", m.nodes[i].name));
    }
  }
  {
    std::vector<bool> reached(static_cast<std::size_t>(m.N()), false);
    std::vector<int> stack;
    for (int i = 0; i < m.N(); ++i) {
      if (touches_boundary[i]) {
        reached[i] = true;
        stack.push_back(i);
      }
    }
    while (!stack.empty()) {
      const int i = stack.back();
      stack.pop_back();
      for (int j : adjacency[i]) {
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

  // Losses.
  if (const toml::node* lv = root.get("loss")) {
    const toml::array* la = lv->as_array();
    if (!la) m.Fail(LineOf(*lv), "'loss' must be an array of tables ([[loss]])");
    for (const toml::node& tv : *la) {
      const toml::table* tt = tv.as_table();
      const int line = LineOf(tv);
      if (!tt) m.Fail(line, "[[loss]] entries must be tables");
      CheckKeys(*tt,
                {"name", "description", "power_W", "shares", "temperature_coefficient_per_K",
                 "temperature_nodes", "reference", "reference_C"},
                "[[loss]]", source);
      LossTerm t;
      t.line = line;
      t.name = (*tt)["name"].value_or(fmt::format("loss at line {}", line));
      const toml::node* p = tt->get("power_W");
      if (!p) m.Fail(line, fmt::format("loss '{}': missing power_W", t.name));
      t.power_W = m.Compile(*p, "power_W", true);
      const toml::table* shares = (*tt)["shares"].as_table();
      if (!shares || shares->empty()) {
        m.Fail(line, fmt::format("loss '{}': missing shares = {{ node = fraction, ... }}", t.name));
      }
      for (const auto& [k, v] : *shares) {
        auto it = index.find(std::string(k.str()));
        if (it == index.end()) {
          m.Fail(LineOf(v), fmt::format("loss '{}': share for unknown node '{}'", t.name, k.str()));
        }
        const double s = m.Compile(v, fmt::format("shares.{}", k.str()), false).value;
        if (s < 0.0) {
          m.Fail(LineOf(v), fmt::format("loss '{}': negative share for node '{}'", t.name, k.str()));
        }
        t.shares.emplace_back(it->second, s);
      }
      if (const toml::node* a = tt->get("temperature_coefficient_per_K")) {
        t.alpha_per_K = m.Compile(*a, "temperature_coefficient_per_K", false).value;
      }
      if (t.alpha_per_K != 0.0) {
        const toml::array* tn = (*tt)["temperature_nodes"].as_array();
        if (!tn || tn->empty()) {
          m.Fail(line, fmt::format("loss '{}': temperature_coefficient_per_K needs "
                                   "temperature_nodes",
                                   t.name));
        }
        for (const toml::node& x : *tn) {
          auto s = x.value<std::string>();
          auto it = s ? index.find(*s) : index.end();
          if (it == index.end() || m.state_of_node[it->second] < 0) {
            m.Fail(LineOf(x), fmt::format("loss '{}': temperature node '{}' is not a node with "
                                          "heat capacity",
                                          t.name, s.value_or("?")));
          }
          t.temperature_states.push_back(m.state_of_node[it->second]);
        }
        const bool has_ref = tt->contains("reference");
        const bool has_ref_c = tt->contains("reference_C");
        if (has_ref == has_ref_c) {
          m.Fail(line, fmt::format("loss '{}': give exactly one of reference = \"ambient\"|"
                                   "\"coolant\" or reference_C = <degC>",
                                   t.name));
        }
        if (has_ref) {
          const std::string r = (*tt)["reference"].value_or(std::string{});
          if (r == "ambient") {
            t.reference = kAmbient;
          } else if (r == "coolant") {
            t.reference = kCoolant;
            m.uses_coolant = true;
          } else {
            m.Fail(LineOf(*tt->get("reference")),
                   fmt::format("loss '{}': reference must be \"ambient\" or \"coolant\"", t.name));
          }
        } else {
          t.reference_degC = m.Compile(*tt->get("reference_C"), "reference_C", false).value;
        }
      }
      m.losses.push_back(std::move(t));
    }
  }

  // Winding weights: the temperature nodes of the temperature-dependent losses.
  m.winding_weights = Eigen::VectorXd::Zero(m.n());
  {
    std::set<int> states;
    for (const LossTerm& t : m.losses) {
      if (t.alpha_per_K > 0.0) states.insert(t.temperature_states.begin(), t.temperature_states.end());
    }
    for (int s : states) m.winding_weights(s) = 1.0 / static_cast<double>(states.size());
  }

  // Singular massless sub-networks: check each connected group of massless nodes.
  {
    std::vector<int> group(static_cast<std::size_t>(m.N()), -1);
    int groups = 0;
    for (int start : m.node_of_massless) {
      if (group[start] >= 0) continue;
      std::vector<int> stack{start};
      group[start] = groups;
      while (!stack.empty()) {
        const int i = stack.back();
        stack.pop_back();
        for (int j : adjacency[i]) {
          if (m.nodes[j].massless && group[j] < 0) {
            group[j] = groups;
            stack.push_back(j);
          }
        }
      }
      ++groups;
    }
    m.SetInputs(ThermalInputs{});
    for (int gidx = 0; gidx < groups; ++gidx) {
      std::vector<int> members;
      for (int i = 0; i < m.N(); ++i) {
        if (group[i] == gidx) members.push_back(i);
      }
      const int k = static_cast<int>(members.size());
      Eigen::MatrixXd y = Eigen::MatrixXd::Zero(k, k);
      double scale = 0.0;
      for (const Edge& e : m.edges) {
        const double g = 1.0 / e.resistance_K_per_W.Eval();
        scale = std::max(scale, std::abs(g));
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
      if (!lu.isInvertible()) {
        std::string names;
        for (int i : members) names += fmt::format("{}'{}' (line {})", names.empty() ? "" : ", ",
                                                  m.nodes[i].name, m.nodes[i].line);
        m.Fail(m.nodes[members.front()].line,
               fmt::format("massless nodes {} form a singular sub-network: Y22 of eq. S25 "
                           "cannot be inverted",
                           names));
      }
    }
    if (!m.Reduce(m.cached)) m.Fail(1, "the massless sub-network is singular");
  }
  m.p0.setZero(m.N());
  m.d.setZero(m.N(), m.n());
  return ThermalModel(std::move(impl));
}

const std::string& ThermalModel::Name() const { return impl_->name; }
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

void ThermalModel::Linearise(const ThermalInputs& in, ThermalLinearModel& out) const {
  const Impl& m = *impl_;
  m.SetInputs(in);
  const Reduced& r = m.Current();
  const Eigen::Vector2d tb(m.vars->ambient_C, m.vars->coolant_C);
  out.a_per_s.resize(m.n(), m.n());
  out.f_K_per_s.resize(m.n());
  out.a_per_s = r.a_red;
  out.f_K_per_s.noalias() = r.b_b * tb;
  // A + G D and B_b T_b + G p0, one loss term at a time: each term touches only the columns of
  // G of its share nodes and the columns of A of its temperature nodes (cheaper than G * D).
  for (const LossTerm& t : m.losses) {
    const double p = t.power_W.Eval();
    double scale0 = 1.0;
    if (t.alpha_per_K != 0.0) {
      const double ref = t.reference == 0 ? t.reference_degC : m.Boundary(t.reference);
      scale0 = 1.0 - t.alpha_per_K * ref;
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
}

Eigen::VectorXd ThermalModel::NodeLosses_W(const ThermalInputs& in,
                                           const Eigen::VectorXd& x_degC) const {
  const Impl& m = *impl_;
  m.SetInputs(in);
  m.LossModel();
  return m.p0 + m.d * x_degC;
}

Eigen::VectorXd ThermalModel::AllTemperatures_degC(const ThermalInputs& in,
                                                   const Eigen::VectorXd& x_degC) const {
  const Impl& m = *impl_;
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
  if (!lu.isInvertible()) throw std::domain_error("thermal model: singular system, no steady state");
  return lu.solve(-lin.f_K_per_s);
}

}  // namespace pumptherm::estimators
