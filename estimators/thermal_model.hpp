#pragma once
/// Lumped-parameter thermal network read from a model file (TOML; schema in
/// docs/thermal-model.md), assembled by Kirchhoff's current law with the massless nodes
/// eliminated by Kron reduction.
///
/// Saheba, Rotea, Wasynczuk, Pekarek, Jordan, "Virtual thermal sensing for electric machines",
/// IEEE Control Systems Magazine 30(1), Feb. 2010, pp. 42-56:
///  - KCL at every node (sidebar eqs. S1-S15):  C dx/dt = Y11 x + Y12 z + Bx u,
///                                               0     = Y21 x + Y22 z + Bz u,
///    x the temperatures of the nodes with heat capacity, z those of the massless nodes;
///  - Kron reduction (eq. S25):  A = Y11 - Y12 Y22^-1 Y21, and likewise for the inputs;
///  - losses (eqs. 1-8): P_Cu = (ia^2 + ib^2 + ic^2) R0 (1 + alpha (T - T0)), split between nodes;
///    the temperature dependence makes the system matrix depend on the operating point
///    (eqs. 12-16: u = u0 + D x).
///
/// Temperatures are absolute (degC) here; the boundaries (ambient, coolant) are inputs.
/// Every resistance, capacity, loss power and share may be a number or a muParser expression of
/// the file's parameters; resistances and loss powers may also use the inputs (speed, currents,
/// boundary temperatures), so effects are added by editing files, not code.
///
/// Pure library: parses text handed to it, does no I/O.

#include <Eigen/Dense>
#include <functional>
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace pumptherm::estimators {

/// A model file that does not parse or does not describe a usable network. The message names
/// the source, the line and the node, edge or key at fault.
class ThermalModelError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// The inputs of the network at one instant.
struct ThermalInputs {
  double speed_rpm = 0.0;      ///< mechanical speed
  double id_A = 0.0;           ///< d-axis current, amplitude-invariant dq (peak phase amplitude)
  double iq_A = 0.0;           ///< q-axis current, amplitude-invariant dq
  double ambient_degC = 25.0;  ///< ambient temperature
  double coolant_degC = 25.0;  ///< coolant temperature (used only by models with a coolant)
};

/// Inputs a fraction w (0..1) of the way from `a` to `b`, every field linearly.
inline ThermalInputs InterpolateInputs(const ThermalInputs& a, const ThermalInputs& b, double w) {
  auto mix = [w](double p, double q) { return p + w * (q - p); };
  return ThermalInputs{mix(a.speed_rpm, b.speed_rpm), mix(a.id_A, b.id_A), mix(a.iq_A, b.iq_A),
                       mix(a.ambient_degC, b.ambient_degC), mix(a.coolant_degC, b.coolant_degC)};
}

/// ia^2 + ib^2 + ic^2 for amplitude-invariant dq currents: 1.5 (id^2 + iq^2), A^2.
inline double PhaseCurrentSquareSum_A2(double id_A, double iq_A) {
  return 1.5 * (id_A * id_A + iq_A * iq_A);
}

/// How the parser reaches the files a model names (loss maps and curves, `[[table]]`). The
/// parser stays pure: it joins `directory` (the model file's directory; empty = none) and the
/// relative path as text, and asks `read` for the file's contents. `read` throws (any
/// std::exception) when the file cannot be read; the parser turns that into a ThermalModelError
/// naming the model file, the line and the table. Without `read`, a model with tables is an
/// error.
struct ThermalModelFiles {
  std::string directory;
  std::function<std::string(const std::string& path)> read;
};

/// The network linearised at one operating point: dx/dt = a x + f, with
///  a (n x n, 1/s) = C^-1 (A_red + G D)        (eq. S25, eqs. 12-16)
///  f (n, K/s)    = C^-1 (B_b T_b + G p0)
/// where A_red is the Kron-reduced conductance matrix, B_b the boundary coupling, G maps the
/// losses of all nodes onto the capacitive ones, p0 the losses at zero temperature and D their
/// temperature sensitivity (W/K).
struct ThermalLinearModel {
  Eigen::MatrixXd a_per_s;
  Eigen::VectorXd f_K_per_s;
};

/// The losses' share of dx/dt at one estimate, split by what makes them (K/s per state):
///  current_K_per_s = (a x + f) at standstill (speed 0, the currents kept) - at rest (speed and
///                    currents 0): the losses of the currents alone (the copper's);
///  speed_K_per_s   = (a x + f) at the inputs - at standstill: the losses of the speed (iron,
///                    rotor, friction).
/// Their sum is the share of every loss the inputs make.
struct ThermalLossRates {
  Eigen::VectorXd current_K_per_s;
  Eigen::VectorXd speed_K_per_s;
};

/// The model's typical operation, from its optional `[operating_range]` table: the defaults of
/// tools that need operating points (sensor placement).
struct ThermalOperatingRange {
  double speed_rpm = 0.0;        ///< typical mechanical speed
  std::vector<double> iq_A;      ///< q-axis currents spanning the typical load (1 to 8)
  double scale_current_A = 0.0;  ///< a sustained high load (the scaling run's current)
};

/// How one node was declared.
struct ThermalNodeInfo {
  std::string name;
  bool massless = false;
  int line = 0;  ///< line in the model file
};

/// A thermal network. Not copyable (it owns compiled expressions); movable. The const member
/// functions share internal scratch space (expression variables, the reduced network for
/// input-dependent resistances): use one model object per thread.
class ThermalModel {
 public:
  /// Parses and validates a model file. `source` names it in error messages (a path, or the
  /// shipped model's name). Throws ThermalModelError naming line and node/edge/key: syntax
  /// errors, unknown keys, duplicate or unknown node names, negative or non-finite capacity,
  /// zero resistance, a node without any edge, a group of nodes without a path to a boundary,
  /// a singular massless sub-network, bad expressions. Negative resistances are legal (the
  /// T-equivalent conduction elements of Saheba 2010 Table 2 need them).
  /// Tables (`[[table]]`) are read through `files` (paths relative to `files.directory`); their
  /// CSV errors name the table file, its line and column.
  static ThermalModel Parse(std::string_view toml_text, const std::string& source,
                            const ThermalModelFiles& files = {});

  ThermalModel(ThermalModel&&) noexcept;
  ThermalModel& operator=(ThermalModel&&) noexcept;
  ~ThermalModel();

  const std::string& Name() const;
  /// The `[operating_range]` table, or nullptr when the file has none.
  const ThermalOperatingRange* OperatingRange() const;
  /// All nodes in file order.
  const std::vector<ThermalNodeInfo>& Nodes() const;
  /// Number of states n (nodes with heat capacity).
  int StateCount() const;
  /// Names of the states, in state order (file order of the capacitive nodes).
  const std::vector<std::string>& StateNames() const;
  /// State index of a capacitive node, or -1 if there is no such capacitive node.
  int StateIndex(std::string_view node) const;
  /// Heat capacities of the states, J/K (n).
  const Eigen::VectorXd& Capacities_J_per_K() const;
  /// Whether any edge touches the coolant boundary (then inputs need `coolant_C`).
  bool UsesCoolant() const;
  /// Whether Linearise accepts `in`: every input finite (the coolant only when the model has one).
  bool AcceptsInputs(const ThermalInputs& in) const;
  /// Whether resistances depend on the inputs (then the reduction is redone per evaluation).
  bool ResistancesVary() const;
  /// State weights of the temperature that the winding resistance reflects (the mean of the
  /// copper loss terms' temperature nodes; n, sums to 1). Zero vector if the model has no
  /// temperature-dependent loss.
  const Eigen::VectorXd& WindingWeights() const;

  /// Whether any expression reads a node temperature (`<node>_C`). Such terms are evaluated at
  /// the temperatures handed to Linearise(in, x, out) and held over the step (their dependence on
  /// temperature is not part of `a`; the `temperature_coefficient_per_K` terms are).
  bool UsesNodeTemperatures() const;

  /// Linearises the network at `in` into `out` (resized on first use; no allocation afterwards
  /// when the resistances are constant). Expressions reading node temperatures see the
  /// temperatures of the last call that gave them (25 degC before any). Throws std::domain_error
  /// when an input is not finite or the massless sub-network becomes singular at this operating
  /// point.
  void Linearise(const ThermalInputs& in, ThermalLinearModel& out) const;

  /// As above, with the states' temperatures `x_degC` (n) for expressions that read node
  /// temperatures. Throws std::domain_error also when `x_degC` is not finite or not of size n.
  void Linearise(const ThermalInputs& in, const Eigen::VectorXd& x_degC,
                 ThermalLinearModel& out) const;

  /// As above, and the losses' share of dx/dt at `x_degC` (ThermalLossRates). On a network whose
  /// resistances are constant only the losses that read the speed or the currents are evaluated
  /// again (none where a loss's value at rest is a constant), else the network is linearised at
  /// standstill and at rest too.
  void Linearise(const ThermalInputs& in, const Eigen::VectorXd& x_degC, ThermalLinearModel& out,
                 ThermalLossRates& rates) const;

  /// Losses per node (all nodes, file order), W, at temperatures `x_degC` of the states.
  Eigen::VectorXd NodeLosses_W(const ThermalInputs& in, const Eigen::VectorXd& x_degC) const;

  /// Temperatures of all nodes (file order), degC: the states copied, the massless nodes solved
  /// from KCL (eq. S25's eliminated equations) at `in`.
  Eigen::VectorXd AllTemperatures_degC(const ThermalInputs& in,
                                       const Eigen::VectorXd& x_degC) const;

  /// The linear map from states to all node temperatures at `in` (N x n): all = M x + m0. Used
  /// to carry covariances to massless nodes.
  Eigen::MatrixXd AllTemperatureJacobian(const ThermalInputs& in) const;

  /// Steady state of the states at constant inputs: solves a x + f = 0. Throws std::domain_error
  /// when the linearised system is singular (no path to a boundary).
  Eigen::VectorXd SteadyState_degC(const ThermalInputs& in) const;

 private:
  struct Impl;
  explicit ThermalModel(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace pumptherm::estimators
