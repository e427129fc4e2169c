#pragma once
/// One interface over the thermal filters a pump may publish (in the manner of Drake's
/// GaussianStateObserver: set and get the estimate and its covariance): the virtual thermal
/// sensor of Saheba et al. 2010 (VirtualThermalSensor) and the same network with its model error
/// in states made for it (DisturbanceThermalSensor). The pump estimator holds one of them and
/// never asks which.
///
/// The filter's state is the network's nodes (model order, the first NodeCount() entries) and
/// whatever the filter adds (the frame sensor's lag and offset, disturbances, reading biases);
/// State() and Covariance() are the whole of it, for saving across a restart.
///
/// Pure library: time enters as dt_s; health is data (ObserverReport), nothing is thrown by
/// Step().

#include <Eigen/Dense>
#include <cstdint>
#include <limits>

#include "estimators/kalman_filter.hpp"
#include "estimators/thermal_model.hpp"

namespace pumptherm::estimators {

/// The readings of one period; NaN = not read this period.
struct ThermalReadings {
  double frame_degC = std::numeric_limits<double>::quiet_NaN();  ///< the frame sensor
  /// The resistance-based winding temperature (Han et al. 2019 eq. 3), a reading of the model's
  /// winding weights, and its sd (NaN: the filter's configured winding sd).
  double winding_degC = std::numeric_limits<double>::quiet_NaN();
  double winding_sd_K = std::numeric_limits<double>::quiet_NaN();
  /// The magnet reading z = T_magnet + g T_winding (the back-EMF row, docs/virtual-sensor.md,
  /// "Magnet temperature from the flux"), its white sd and g (dimensionless).
  double magnet_degC = std::numeric_limits<double>::quiet_NaN();
  double magnet_sd_K = std::numeric_limits<double>::quiet_NaN();
  double magnet_winding_gain = 0.0;
  /// How far the magnet reading moves per volt of a constant error in the drive's reported q
  /// voltage (its inverter's dead time), K/V: the line is fitted to uq/w, so such an error moves
  /// it by e/w, more at low speed (MagnetFluxReading). 0: the reading has no such error.
  double magnet_voltage_gain_K_per_V = 0.0;
  /// The drive's q-axis voltage averaged over the period, less its known terms
  /// (QAxisKnownTerms_V), at the period's mean q current and electrical speed, and the white sd
  /// of that mean (estimators/voltage_equation.hpp); NaN uq: none.
  double uq_V = std::numeric_limits<double>::quiet_NaN();
  double uq_sd_V = std::numeric_limits<double>::quiet_NaN();
  double iq_A = std::numeric_limits<double>::quiet_NaN();
  double w_rad_per_s = std::numeric_limits<double>::quiet_NaN();
};

/// One reading's row in an update: whether it was fused, its innovation y - C x- (K) and that
/// innovation's variance (C S- C^T + Sm, K^2); NaN when it was not fused.
struct ReadingRow {
  bool fused = false;
  double innovation_K = std::numeric_limits<double>::quiet_NaN();
  double innovation_var_K2 = std::numeric_limits<double>::quiet_NaN();
  /// The normalised innovation squared of this row alone (innovation^2 / variance).
  double Nis() const { return innovation_K * innovation_K / innovation_var_K2; }
};

/// What one observer step did: the filter's update report and each reading's row.
struct ObserverReport {
  const KalmanUpdateReport* update = nullptr;
  ReadingRow frame, winding, magnet, voltage;
  /// The step was refused (non-finite inputs or period, or a model that cannot be linearised
  /// there): nothing changed.
  bool refused = false;
  /// Readings left out as invalid (an sd that is not positive and finite, a non-finite gain).
  int rejected_readings = 0;
};

class ThermalObserver {
 public:
  virtual ~ThermalObserver() = default;

  /// Nodes of the network (the model's states); the filter's state has at least as many.
  virtual int NodeCount() const = 0;
  /// Every entry of the filter's state.
  virtual int StateCount() const = 0;

  /// Every node (and the sensor's lag) at `x0_degC`, with the configured initial covariance;
  /// whatever else the filter estimates at its prior.
  virtual void Initialise(double x0_degC) = 0;
  /// Every node (and the sensor's lag) at `x0_degC` within `sd_K` each, independently: a cold
  /// start, the pump at rest at its frame's temperature; the rest at its prior.
  virtual void InitialiseKnown(double x0_degC, double sd_K) = 0;
  /// Starts from node temperatures `x_degC` (n) with their covariance `s_K2` (n x n), the rest
  /// at its prior (a restart from a state that kept the nodes alone). Throws
  /// std::invalid_argument for wrong sizes or non-finite values.
  virtual void InitialiseNodes(const Eigen::VectorXd& x_degC, const Eigen::MatrixXd& s_K2) = 0;

  /// One period of `dt_s` with `inputs` held over it, then the update with `readings`. A period
  /// that is not positive and finite, or inputs the model cannot take, refuse the step.
  virtual const ObserverReport& Step(const ThermalInputs& inputs, double dt_s,
                                     const ThermalReadings& readings) = 0;

  /// The whole filter state and covariance (NodeCount() nodes first).
  virtual const Eigen::VectorXd& State() const = 0;
  virtual const Eigen::MatrixXd& Covariance() const = 0;
  /// Whether `x` (StateCount()) and `s` (square) can be restored: finite, variances not
  /// negative. A filter of another configuration (another count) cannot.
  virtual bool CanRestore(const Eigen::VectorXd& x, const Eigen::MatrixXd& s) const = 0;
  /// Takes the whole state as saved before a restart. Throws std::invalid_argument when
  /// !CanRestore(x, s).
  virtual void Restore(const Eigen::VectorXd& x, const Eigen::MatrixXd& s) = 0;

  /// Node i's estimate, degC, and its sd as reported (with any floor the filter keeps for model
  /// error no state represents), K.
  double Node_degC(int i) const { return State()(i); }
  /// w^T x over the nodes (w of at most NodeCount() entries): e.g. the winding's temperature
  /// from the model's winding weights, degC.
  double Weighted_degC(const Eigen::VectorXd& w) const {
    double sum = 0.0;
    for (int i = 0; i < w.size(); ++i) sum += w(i) * Node_degC(i);
    return sum;
  }
  virtual double NodeSd_K(int i) const = 0;
  /// The variance of w^T x over the nodes (w of size NodeCount()), K^2: e.g. the winding's.
  /// No allocation.
  virtual double WeightedVariance_K2(const Eigen::VectorXd& w) const = 0;
  /// The floor NodeSd_K adds in quadrature to every node's sd (model error no state
  /// represents), K; 0 for a filter without one.
  virtual double SdFloor_K() const { return 0.0; }
  /// The largest node sd that a (re)start leaves to settle, K: the filter has converged once it
  /// is small. Large by design for a node the readings barely see is not counted here (the
  /// disturbance filter's rotor, whose temperature integrates the history of an unknown heat),
  /// only what knowing the level and the dynamics removes.
  virtual double SettlingSd_K() const = 0;
  /// Whether SettlingSd_K() < `sd_K`; a filter may answer without computing it.
  virtual bool SettledWithin(double sd_K) const { return SettlingSd_K() < sd_K; }

  /// Whether the filter models the frame sensor's first-order lag (a state of its own): a
  /// filter that does not fuses the lagging reading as the node itself.
  virtual bool ModelsSensorLag() const { return false; }
  /// Reads the frame sensor with the lag `lag_s` from now (the model diagnosis fitted it): true
  /// when the filter models the lag and took it, false (nothing changed) otherwise.
  virtual bool AdoptSensorLag(double lag_s) {
    (void)lag_s;
    return false;
  }

  /// Adds the heat the filter has found (frame path, rotor) to the forcing of `lin` (n nodes),
  /// so that a forecast with the nominal model carries it. Nothing for a filter without such
  /// states.
  virtual void AddFoundHeat(ThermalLinearModel& lin) const { (void)lin; }

  /// The frame sensor's offset as the filter estimates it, K, its sd, the steps of it found and
  /// their sum (docs/daemon.md, "The pipeline, per pump": a sensor that steps); NaN and 0 for a
  /// filter without it.
  virtual double SensorOffset_K() const { return std::numeric_limits<double>::quiet_NaN(); }
  virtual double SensorOffsetSd_K() const { return std::numeric_limits<double>::quiet_NaN(); }
  virtual int SensorSteps() const { return 0; }
  virtual double LastSensorStep_K() const { return std::numeric_limits<double>::quiet_NaN(); }
  virtual double SteppedOffset_K() const { return std::numeric_limits<double>::quiet_NaN(); }
  /// Whether the filter estimates the sensor's offset (then the three below apply).
  virtual bool EstimatesSensorOffset() const { return false; }
  /// The next frame reading may open a step of the offset even though the last step fused none.
  virtual void ReopenSensorOffset() {}
  /// Sets the offset (K), its sd (K) and the sum of its steps, as saved before a restart.
  /// Throws std::invalid_argument for non-finite values or an sd that is not positive.
  virtual void RestoreSensorOffset(double offset_K, double sd_K, double stepped_K) {
    (void)offset_K, (void)sd_K, (void)stepped_K;
  }
  /// The sum of the offset's steps, restored with the whole state (Restore()).
  virtual void RestoreSteppedOffset(double stepped_K) { (void)stepped_K; }

  /// The magnet reading's bias as the filter estimates it, K, and its sd (0 and NaN for a filter
  /// without a bias state: its magnet reading is taken as unbiased), for a reading whose voltage
  /// gain (ThermalReadings::magnet_voltage_gain_K_per_V) is `voltage_gain_K_per_V`: the bias
  /// state plus that gain times the line's voltage-error state, where the filter has one.
  virtual double MagnetBias_K(double voltage_gain_K_per_V) const {
    (void)voltage_gain_K_per_V;
    return 0.0;
  }
  virtual double MagnetBiasSd_K(double voltage_gain_K_per_V) const {
    (void)voltage_gain_K_per_V;
    return std::numeric_limits<double>::quiet_NaN();
  }

  /// The heat on the frame path the filter finds beyond the model's, W (NaN for a filter
  /// without such a state).
  virtual double FrameHeat_W() const { return std::numeric_limits<double>::quiet_NaN(); }
  /// The heat inside the rotor the filter finds beyond the model's, W, and its sd (NaN for a
  /// filter without such a state).
  virtual double RotorHeat_W() const { return std::numeric_limits<double>::quiet_NaN(); }
  virtual double RotorHeatSd_W() const { return std::numeric_limits<double>::quiet_NaN(); }

  /// Whether the filter takes the drive's q-axis voltage as a reading (ThermalReadings::uq_V).
  virtual bool TakesVoltage() const { return false; }
  /// Whether the magnet the voltage gives is calibrated (psi0 learnt against known
  /// temperatures), so that the voltage observes the rotor; until then it does not.
  virtual void SetMagnetObserved(bool observed) { (void)observed; }
  /// Widens the loss scale's sd to at least `sd` (relative): losses stated to be further off the
  /// model's than when the state was saved. Nothing for a filter without a loss scale.
  virtual void WidenLossScale(double sd) { (void)sd; }
  /// The motor file's magnet law is wrong for this pump: from now on the voltage reads the
  /// winding through its resistance alone and leaves the magnet to the thermal model.
  virtual void FreeMagnetLaw() {}
  /// The same for a state restored from one saved after FreeMagnetLaw (its flux already free).
  virtual void RestoreMagnetLawGivenUp() {}
  /// Its calibration as estimated: the relative errors of R0 and psi0 and the voltage offset
  /// (V), with their sds (NaN without the voltage reading).
  struct Calibration {
    double dr = std::numeric_limits<double>::quiet_NaN();
    double dr_sd = std::numeric_limits<double>::quiet_NaN();
    double dpsi = std::numeric_limits<double>::quiet_NaN();
    double dpsi_sd = std::numeric_limits<double>::quiet_NaN();
    double dbeta = std::numeric_limits<double>::quiet_NaN();
    double dbeta_sd = std::numeric_limits<double>::quiet_NaN();
    double u0_V = std::numeric_limits<double>::quiet_NaN();
    double u0_sd_V = std::numeric_limits<double>::quiet_NaN();
  };
  virtual Calibration VoltageCalibration() const { return {}; }
  /// The covariance of the calibration's dr (kR0) or dpsi (kPsi0) with w^T x over the nodes (w
  /// of size NodeCount()): the resistance and flux at the filter's temperatures are products of
  /// the two. 0 without the voltage reading. No allocation.
  enum class CalibrationEntry : std::uint8_t { kR0, kPsi0 };
  virtual double CalibrationCovariance(CalibrationEntry entry, const Eigen::VectorXd& w) const {
    (void)entry;
    (void)w;
    return 0.0;
  }
};

}  // namespace pumptherm::estimators
