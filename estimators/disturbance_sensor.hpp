#pragma once
/// A virtual thermal sensor whose model error goes into states made for it (docs/virtual-sensor.md,
/// "Disturbance states"): the network's nodes (Saheba et al. 2010 eqs. 18-34, with a small
/// process noise: the model is believed) augmented with
///  - the frame sensor's first-order lag, tau ds/dt = T_frame - s (when it has one),
///  - the sensor's constant calibration offset b, y = s + b,
///  - a frame-path disturbance heat d_f (W, a random walk): lost or changed cooling, an
///    unmeasured ambient, anything that heats or cools the frame from outside the model,
///  - optionally a relative loss scale s (every loss times 1 + s, first-order Gauss-Markov:
///    a short-term random walk with a stationary sd; with the voltage rows, a rotor heat state
///    and the magnet calibrated (SetMagnetObserved), every loss but the rotor node's, which are
///    that state's),
///  - a rotor disturbance heat d_r (W, first-order Gauss-Markov with a stationary sd): heat inside
///    that the frame barely sees, so its sd (and the rotor's) says how little is known,
///  - for each slow reading fused besides the frame (the winding from resistance, the magnet
///    from the flux) a bias of that reading (K, first-order Gauss-Markov): their errors are slow
///    (a nameplate flux or R0 a little off, the inverter's voltage error), and taken as white
///    noise at one reading per second the filter would average them away and claim an sd far
///    below the error,
/// and a floor on every reported node sd for the model error no state represents.
///
/// Pure library; no allocation per step once sized (the re-discretisation when the operating
/// point moves allocates, as in VirtualThermalSensor).

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "estimators/frame_sensor_model.hpp"
#include "estimators/kalman_filter.hpp"
#include "estimators/thermal_discretisation.hpp"
#include "estimators/thermal_model.hpp"
#include "estimators/thermal_observer.hpp"
#include "estimators/voltage_equation.hpp"

namespace pumptherm::estimators {

struct DisturbanceSensorConfig {
  std::string measured_node = "frame";
  std::string rotor_node = "rotor";  ///< absent from the model: no rotor heat state
  /// The reading's sd: 0.05 K of noise on 0.1 K steps is 0.058 K as white noise, but on a slowly
  /// moving frame the step error dwells and flips (correlated), and taken as white each flip
  /// moves the frame estimate through the inverted lag; twice that sd keeps the estimate
  /// smoother than the reading (docs/virtual-sensor.md, "The reading's sd").
  double measurement_sd_K = 0.12;
  /// The reading's white sd (0.05 K of noise, 0.1 K steps) for the step test below: two
  /// consecutive readings differ by their noise and at most a step's flip, not by the slow
  /// correlated error measurement_sd_K allows for.
  double sensor_step_noise_sd_K = 0.058;
  double sensor_lag_s = 0.0;         ///< 0: no lag state
  double sensor_offset_sd_K = 0.5;   ///< a priori calibration offset
  double node_process_sd_K = 0.005;  ///< per sqrt(s), every node
  double frame_heat_sd_W = 3.0;      ///< random walk of d_f, W per sqrt(s)
  double rotor_heat_sd_W = 5.0;      ///< stationary sd of d_r, W
  double rotor_heat_tau_s = 1800.0;  ///< its correlation time
  /// Below this |speed| d_r does not heat the rotor: the heat the model may lack there (gas
  /// friction, eddy currents in the rotor, magnet losses) comes with its turning. At rest d_r's
  /// prior would otherwise spread the rotor's temperature for as long as the pump stands, and the
  /// run-up that follows could learn psi0 no better than that spread. 0 = at every speed.
  double rotor_heat_min_speed_rpm = 0.0;
  /// Once the filter finds more rotor heat than this many of d_r's stationary sds, d_r's variance
  /// is held at least at (d_r / this)^2 (an added process noise): heat beyond the prior says the
  /// prior was too narrow for this pump, and a d_r held at the prior's width would keep the
  /// filter confident in its first split of that heat between the rotor and whatever else
  /// explains the readings (the magnet reading's bias, the loss scale, the calibration). 0 = off.
  double rotor_heat_found_sds = 2.0;
  /// Short-term random walk of a relative loss scale s (every loss times 1 + s; with the voltage
  /// rows, a rotor heat state and the magnet calibrated, not the rotor node's losses: those are
  /// d_r's), per sqrt(s); 0 = no state.
  double loss_scale_sd = 0.003;
  /// Stationary sd of s (a first-order Gauss-Markov state whose short-term walk is
  /// loss_scale_sd): how far the model's losses may be off. As a pure random walk, a load that
  /// never changes (the frame cannot tell the losses' scale from frame-path heat then) would let
  /// s, and the interior's sd with it, grow without bound, and x + 2 sd reach a trip level on a
  /// healthy pump.
  double loss_scale_max_sd = 0.3;
  /// sd of s at a start: how far this pump's losses may be off the model's before any reading
  /// says so. A model whose losses were checked against this pump's data (docs/operator-guide.md,
  /// commissioning) is known to about a tenth; one that was not may be off by half (iron losses
  /// x1.5-2), and at a tenth the filter then puts the stator's extra heat on the frame path and
  /// into R0, and the interior runs several kelvin cold inside a narrow band.
  double loss_scale_initial_sd = 0.1;
  /// With the voltage rows: how far the copper loss may still be off, relative, at the loss
  /// scale's stationary sd (the rows measure the resistance; left are the skin and proximity
  /// losses a DC resistance misses, the winding's hot spot against its mean, and dR's own
  /// error). Without them the copper is in the loss scale like every other loss.
  double copper_loss_sd_rel = 0.10;
  double sd_floor_K = 1.0;  ///< added in quadrature to every reported node sd
  /// A step of the reading between readings fused at consecutive steps (or the last one before
  /// a gap and the first after ReopenSensorOffset()) that differs from the step the filter
  /// predicted between them by more than this many sds (two readings' noise and what the
  /// prediction added) is a step of the sensor's offset: the frame cannot move that far in a
  /// step (its heat capacity; the frame-path heat's random walk is in the prediction), a
  /// connector or calibration can. The offset's variance then grows by that difference
  /// squared, so the update gives the step to the offset. 0 = off.
  double sensor_step_gate_sd = 8.0;
  /// Whether the resistance-based winding temperature is fused: the update then has a winding
  /// row (and a bias state); without it a winding reading given to Step() is not used.
  bool winding_reading = false;
  /// Standard deviation of the resistance-based winding temperature when it is fused (white).
  double winding_measurement_sd_K = 3.0;
  /// Stationary sd and correlation time of the winding reading's bias; sd 0 = no bias state.
  double winding_bias_sd_K = 3.0;
  double winding_bias_tau_s = 3600.0;
  /// The node the magnet temperature from the flux measures (with a winding gain, see
  /// DisturbanceReadings); empty or absent from the model = no magnet reading.
  std::string magnet_node;
  /// Stationary sd and correlation time of the magnet reading's bias (a Gauss-Markov state).
  double magnet_bias_sd_K = 3.0;
  double magnet_bias_tau_s = 3600.0;
  /// Least white sd of the magnet reading (its own sd, from the identifier, may be smaller).
  double magnet_min_white_sd_K = 0.3;
  /// Stationary sd and correlation time of the drive's q-voltage error as the magnet reading
  /// sees it (a Gauss-Markov state, V, entering the magnet row with the reading's voltage gain):
  /// the inverter's dead time, whose share of the reading grows as the speed falls, so a cold
  /// start's run-up would otherwise teach the bias state the low-speed error. 0 = no state; off
  /// with the voltage rows (their own offset state takes it).
  double line_voltage_error_sd_V = 0.2;
  double line_voltage_error_tau_s = 86400.0;
  double initial_sd_K = 20.0;  ///< as VirtualSensorConfig
  double initial_spread_sd_K = 5.0;
  /// The drive's q-axis voltage as a reading (estimators/voltage_equation.hpp): an extended row
  /// of the winding (the model's winding weights) and the magnet node, with states for the
  /// relative errors of R0 and psi0 (this pump's, against its nameplate) and for the voltage
  /// offset the drive's known error leaves. Off unless `voltage_reading`.
  bool voltage_reading = false;
  VoltageLaw voltage_law;
  /// The node whose temperature the flux follows (the magnet's; empty: `magnet_node`, else
  /// `rotor_node`).
  std::string voltage_magnet_node;
  double r0_sd_rel = 0.03;    ///< prior sd of R0's relative error (a nameplate: a few percent)
  double psi0_sd_rel = 0.02;  ///< prior sd of psi0's relative error
  /// Prior sd of the magnet's temperature coefficient's relative error; 0 (the default): the
  /// motor file's law is taken as exact and the state stays at 0. With 0.3 the demo's magnet
  /// from flux is 1.2-2.2 K off instead of 0.1-0.4 K, and a law 20 % off still leaves the rotor
  /// 7-14 K off (docs/resistance-identification.md, "A wrong magnet law").
  double magnet_law_sd_rel = 0.0;
  /// Random walk of both relative errors (the motor ageing), per sqrt(h).
  double calibration_walk_per_sqrt_h = 1e-4;
  double voltage_offset_sd_V = 0.1;       ///< stationary sd of the offset (Gauss-Markov)
  double voltage_offset_tau_s = 86400.0;  ///< its correlation time
  /// Least white sd of one period's mean uq: the reading's noise, quantisation and the ripple
  /// that a second's mean does not remove.
  double uq_min_sd_V = 0.003;
  /// Periods over which the voltage's own noise is learnt (0 = not learnt: uq_min_sd_V and the
  /// reading's sd). A drive's report can carry more than its quantisation and sample noise (a
  /// mechanical speed ripple the speed estimate does not show moves the back-EMF by tens of mV
  /// at a fraction of a hertz), and a row trusted beyond its noise teaches the calibration and
  /// the magnet that noise. Learnt from the innovations and from the differences of successive
  /// ones, whichever is smaller: a slow error of the estimate (heat it has not found yet)
  /// cancels in the differences, the noise does not.
  double uq_noise_learn_periods = 30.0;
  /// A voltage row whose innovation lies beyond this many of its sds is left out (an outlier:
  /// a transient the steady-state equation does not describe).
  double voltage_gate_sd = 5.0;
  /// A voltage row beyond its gate this many periods running is no transient: the filter is what
  /// is off (heat of a size it did not expect arrived on the magnet's side). From then on the
  /// magnet node's variance is raised until the row's innovation sits at the gate and the row is
  /// fused, so the estimate follows the voltage instead of never taking it again. 0 = never.
  int voltage_gate_release_periods = 10;
  /// Random walk of psi0's relative error once the magnet law is given up (FreeMagnetLaw), per
  /// sqrt(s): the flux then follows whatever the magnet does. It must outrun the fastest drift
  /// of the flux a magnet can make (0.13 %/K at 2 K/min: 4e-5 per s) within a few periods, for
  /// a flux change the walk does not cover reads as winding (1 % of the flux is about 100 K of
  /// winding at 3 A), while a load step still reads as resistance (0.3 V per A against a walk of
  /// 4 mV per period).
  double free_flux_walk_per_sqrt_s = 1e-4;
};

/// The readings of one period (the observer interface's).
using DisturbanceReadings = ThermalReadings;

/// Whether the boundary (ambient and coolant) reaches the network through `measured_node` alone:
/// after the massless nodes are reduced, a change of the boundary temperature moves no other
/// node's derivative directly (f of ThermalLinearModel, at standstill, every node at the
/// boundary's temperature). Only then can the frame-path disturbance heat stand for every change
/// on the cooling path (lost cooling, an unmeasured ambient); a model whose rotor has its own path
/// to the ambient (wallscheid2017-4node) leaves such a change to the rotor heat state, which
/// takes it for heat inside. False for a node the model lacks. Throws std::domain_error when the
/// model cannot be linearised at standstill.
bool BoundaryOnlyThrough(const ThermalModel& model, const std::string& measured_node);

class DisturbanceThermalSensor : public ThermalObserver {
 public:
  /// Throws std::invalid_argument naming an unknown measured node or a bad setting.
  DisturbanceThermalSensor(const ThermalModel& model, DisturbanceSensorConfig config);

  int NodeCount() const override { return n_; }
  int StateCount() const override { return n_aug_; }
  void Initialise(double x0_degC) override;
  void InitialiseKnown(double x0_degC, double sd_K) override;
  /// The sensor's lag state at the measured node (its row of `s_K2`), every disturbance and
  /// bias at zero with its prior sd as Initialise(double).
  void InitialiseNodes(const Eigen::VectorXd& x_degC, const Eigen::MatrixXd& s_K2) override;
  /// One period with every reading. The update has one row per reading the filter has a state
  /// for (frame, winding, magnet, in this order) whenever any is finite; a missing reading's row
  /// is zero (no effect). The winding's own sd in `readings` is not used (the filter's
  /// winding_measurement_sd_K is, with the reading's bias state). A refused step changes
  /// nothing.
  const ObserverReport& Step(const ThermalInputs& inputs, double dt_s,
                             const ThermalReadings& readings) override;

  const Eigen::VectorXd& State() const override { return filter_.State(); }
  const Eigen::MatrixXd& Covariance() const override { return filter_.Covariance(); }
  /// Node i's sd with the floor (sd_floor_K in quadrature).
  double NodeSd_K(int i) const override;
  double WeightedVariance_K2(const Eigen::VectorXd& w) const override;
  double SdFloor_K() const override { return config_.sd_floor_K; }
  /// The largest node sd the filter would have if its disturbances, biases and the sensor's
  /// offset were known (the node block's Schur complement, floor included): what a start or a
  /// restart leaves to settle. The rotor's large sd without a magnet reading comes from the rotor
  /// heat state and is not counted.
  double SettlingSd_K() const override;
  /// Without the Schur complement while every counted node's own sd, floor included, is below
  /// `sd_K`: conditioning on the other states never widens a node.
  bool SettledWithin(double sd_K) const override;
  /// Every node's estimate and reported sd into `x_degC`, `sd_K` (sized n; no allocation).
  void Nodes(Eigen::VectorXd& x_degC, Eigen::VectorXd& sd_K) const;
  /// Adds the disturbance heats (frame path, rotor) to the forcing of `lin` (n nodes), so that a
  /// forecast with the nominal model carries the heat the filter has found.
  void AddFoundHeat(ThermalLinearModel& lin) const override;
  bool ModelsSensorLag() const override { return sensor_model_.has_lag(); }
  bool AdoptSensorLag(double lag_s) override;
  double FrameHeat_W() const override { return filter_.State()(df_); }
  double RotorHeat_W() const override {
    return dr_ >= 0 ? filter_.State()(dr_) : std::numeric_limits<double>::quiet_NaN();
  }
  double RotorHeatSd_W() const override {
    return dr_ >= 0 ? std::sqrt(std::max(filter_.Covariance()(dr_, dr_), 0.0))
                    : std::numeric_limits<double>::quiet_NaN();
  }
  bool EstimatesSensorOffset() const override { return true; }
  double SensorOffset_K() const override { return filter_.State()(sensor_model_.offset()); }
  double SensorOffsetSd_K() const override {
    const int b = sensor_model_.offset();
    return std::sqrt(std::max(filter_.Covariance()(b, b), 0.0));
  }
  /// Steps of the sensor's offset found so far (sensor_step_gate_sd), the last one's size (the
  /// reading's step less the predicted one, K; 0 before any) and the sum of the steps since the
  /// last Initialise (how far the reading stepped away from the frame, K: a slow drift of the
  /// offset state is not in it).
  int SensorSteps() const override { return sensor_steps_; }
  double LastSensorStep_K() const override { return last_sensor_step_K_; }
  double SteppedOffset_K() const override { return stepped_offset_K_; }
  /// Sets the sensor's offset estimate (K), its sd (K, uncorrelated with the rest) and the sum of
  /// its steps (SteppedOffset_K), as saved before a restart, after Initialise. Throws
  /// std::invalid_argument for a non-finite value or an sd that is not positive.
  void RestoreSensorOffset(double offset_K, double sd_K, double stepped_K) override;
  bool CanRestore(const Eigen::VectorXd& x, const Eigen::MatrixXd& s) const override;
  /// Takes the whole state as saved before a restart (State(), Covariance(): the nodes, the
  /// sensor's lag and offset, the disturbances and biases, with their correlations), so that
  /// what the filter had found (lost cooling, heat inside, a stepped sensor) outlives the
  /// restart; the last reading is forgotten (no step test against a reading before it). Throws
  /// std::invalid_argument when !CanRestore(x, s).
  void Restore(const Eigen::VectorXd& x, const Eigen::MatrixXd& s) override;
  /// The sum of the offset's steps as saved (after Restore). Throws std::invalid_argument when
  /// it is not finite.
  void RestoreSteppedOffset(double stepped_K) override;
  /// The next fused frame reading may open a step of the offset even though the previous step
  /// fused none (a sensor back from a fault that left it out, such as a jump beyond physics).
  void ReopenSensorOffset() override { reopen_offset_ = true; }
  bool TakesVoltage() const override { return row_v_ >= 0; }
  /// While the voltage observes the rotor the rotor node's losses are the rotor heat state's,
  /// not the loss scale's (LossColumns).
  void SetMagnetObserved(bool observed) override { magnet_observed_ = observed && !law_free_; }
  /// The motor file's magnet law is given up for the rest of the run: the flux the voltage row
  /// reads no longer follows the magnet node (its law's coefficient 0 in the row, the present
  /// law's factor folded into psi0's error, which then walks at free_flux_walk_per_sqrt_s), so
  /// the voltage measures the winding through the resistance its load changes show and no
  /// longer the rotor. The rotor heat that the law made the filter find is forgotten: its state
  /// goes back to 0, with its prior variance plus its square, and the nodes' covariance takes
  /// the steady-state effect of the heat it had, so the rotor's sd covers what it had held.
  void FreeMagnetLaw() override;
  void WidenLossScale(double sd) override;
  void RestoreMagnetLawGivenUp() override;
  Calibration VoltageCalibration() const override;
  double CalibrationCovariance(CalibrationEntry entry, const Eigen::VectorXd& w) const override;
  double MagnetBias_K(double voltage_gain_K_per_V) const override;
  double MagnetBiasSd_K(double voltage_gain_K_per_V) const override;
  const KalmanFilter& Filter() const { return filter_; }

 private:
  const ThermalModel& model_;
  DisturbanceSensorConfig config_;
  FrameSensorModel sensor_model_;
  void BuildRows();
  void GaussMarkov(int state, double sd, double tau_s, double dt_s);
  /// The time update of one period (false: refused, nothing changed).
  bool Predict(const ThermalInputs& in, double dt_s);
  /// Which readings of `r` enter this step's update.
  struct Used {
    bool frame = false, winding = false, magnet = false, voltage = false;
    bool Any() const { return frame || winding || magnet || voltage; }
  };
  /// This period's voltage innovation into the learnt noise; the row's sd: at least that noise.
  double LearnVoltageNoise(double innovation_V, double reading_sd_V);
  /// The learnt noise back at uq_min_sd_V (a start; no innovation remembered).
  void ForgetVoltageNoise();
  /// The update rows of this step's readings into c_all_, y_all_, sm_all_.
  void FillRows(const ThermalReadings& r, const Used& used);
  /// The voltage row (extended: linearised at the predicted state); false when its innovation
  /// fails the gate (voltage_gate_sd).
  bool VoltageRow(const ThermalReadings& r);
  /// What d_r's variance lacks of (d_r / rotor_heat_found_sds)^2 once d_r is beyond that many
  /// stationary sds (W^2; 0 otherwise).
  double RotorHeatDeficit_W2() const;
  /// The voltage row's innovation variance c S- c^T + sd^2.
  double RowVariance(double sd);
  /// The loss scale's and dR's columns of heat_in_ at the predicted operating point.
  void LossColumns();
  /// The report's rows from the update.
  void ReportRows(const KalmanUpdateReport& update, const Used& used);
  /// Every node and the lag at `x0_degC` with a common sd and one of each's own; the rest at its
  /// prior.
  void InitialiseWith(double x0_degC, double common_sd_K, double spread_sd_K);
  /// FreeMagnetLaw's two changes of the state: the flux law's present factor into psi0's error
  /// (a linear change of variables, covariance included), and the rotor heat forgotten.
  void FoldFluxLaw(Eigen::VectorXd& x, Eigen::MatrixXd& s) const;
  void ForgetRotorHeat(Eigen::VectorXd& x, Eigen::MatrixXd& s) const;
  /// The priors of the voltage reading's states into `x`, `s`.
  void VoltagePriors(Eigen::VectorXd& x, Eigen::MatrixXd& s) const;
  /// The sensor-offset step test on the predicted state (sensor_step_gate_sd).
  void OpenOffsetOnStep(double frame_degC);
  /// After an update with a frame reading: that reading and the filter's reading of it.
  void RememberReading(double frame_degC);

  int n_ = 0, df_ = 0, dr_ = -1, ls_ = -1, n_aug_ = 0, rotor_ = -1;
  int wb_ = -1, mb_ = -1, magnet_ = -1;  ///< winding and magnet reading biases, the magnet node
  int mu_ = -1;                          ///< the magnet reading's voltage error, V (-1: none)
  int row_w_ = -1, row_m_ = -1;          ///< their rows in the update (-1: none)
  /// The voltage reading: R0's and psi0's relative errors, the offset, the flux's node, its row.
  int dr_state_ = -1, dpsi_ = -1, dbeta_ = -1, u0_ = -1, vmagnet_ = -1, row_v_ = -1;
  Eigen::RowVectorXd cv_row_;              ///< this step's voltage row (1 x n_aug)
  std::vector<Eigen::Index> row_nonzero_;  ///< its nonzero coefficients (the gate's workspace)
  double yv_ = 0.0;                        ///< its linearised observation
  double uq_sd_V_ = 0.0;                   ///< its sd
  int voltage_rejected_run_ = 0;           ///< voltage rows beyond the gate in a row
  /// A mean of absolute values learnt over uq_noise_learn_periods (LearnVoltageNoise).
  struct AbsMean {
    double mean = 0.0;
    double count = 0.0;  ///< values added since the start
    void Reset(double assumed);
    void Add(double value, double periods);
  };
  /// The voltage's learnt noise: the mean |innovation| and |difference of successive
  /// innovations|, V, and the last period's innovation (NaN: that period had no voltage row).
  AbsMean uq_innovation_, uq_innovation_step_;
  double last_innovation_V_ = std::numeric_limits<double>::quiet_NaN();
  bool frame_fused_last_ = false;  ///< the previous step fused a frame reading
  bool magnet_observed_ = false;   ///< SetMagnetObserved
  bool law_free_ = false;          ///< FreeMagnetLaw
  /// The last fused frame reading, the filter's reading of it after that update and its variance.
  double last_reading_degC_ = std::numeric_limits<double>::quiet_NaN();
  double last_predicted_degC_ = 0.0;
  double last_predicted_var_K2_ = 0.0;
  bool reopen_offset_ = false;
  int sensor_steps_ = 0;
  double last_sensor_step_K_ = 0.0;
  double stepped_offset_K_ = 0.0;
  ThermalLinearModel lin_, lin_block_;
  ThermalLossRates loss_rates_;  ///< the losses' share of dx/dt at the estimate (LossColumns)
  ThermalDiscretiser discretiser_;
  KalmanFilter filter_;
  ObserverReport report_;
  KalmanUpdateReport refused_;  // the update report of a refused step
  Eigen::MatrixXd ad_;
  Eigen::VectorXd sp_;  ///< Sp's diagonal: the states' process noise is uncorrelated
  Eigen::VectorXd bu_, x_nodes_;
  Eigen::MatrixXd c0_, sm0_;  ///< no reading: an update of no rows
  Eigen::VectorXd y0_;
  /// d_f, d_r, s and dR into the nodes (K/s per unit of each).
  Eigen::MatrixXd heat_in_;
  Eigen::MatrixXd c_all_, sm_all_;   ///< every reading's row (m x n_aug, m x m)
  Eigen::MatrixXd cw_row_, cm_row_;  ///< the winding and magnet rows (1 x n_aug), magnet without g
  Eigen::VectorXd y_all_;
  /// Workspaces of WeightedVariance_K2 and SettlingSd_K (const queries, no allocation).
  mutable Eigen::VectorXd sw_;
  mutable Eigen::MatrixXd aux_cov_, aux_cross_, aux_solved_;
  mutable Eigen::LDLT<Eigen::MatrixXd> aux_ldlt_;
  /// Per state, the period of the last GaussMarkov() call and its e^(-dt/tau).
  std::vector<std::pair<double, double>> gauss_markov_;
};

}  // namespace pumptherm::estimators
