#pragma once
/// Model-mismatch detection and naming, online, for one pump (docs/virtual-sensor.md, "Model
/// mismatch").
///
/// A separate low-noise Kalman filter runs on the nominal model (the published filter absorbs
/// model error into its process noise and so cannot see it). Its state is the network's nodes,
/// the measuring sensor's first-order lag (tau ds/dt = T - s, when the sensor has one) and the
/// sensor's constant calibration offset b (y = s + b). Detection: the sum of the last W
/// normalised innovations squared is chi-square with W degrees of freedom while the model holds
/// (Bar-Shalom, Li, Kirubarajan, "Estimation with Applications to Tracking and Navigation",
/// Wiley 2001, section 5.4.2, the time-average NIS test); above its (1 - p) quantile the model
/// is declared wrong.
///
/// Naming: the generalised likelihood ratio of Willsky and Jones ("A generalized likelihood
/// ratio approach to the detection and estimation of jumps in linear systems", IEEE TAC 21(1),
/// 1976, eqs. 11-20) for each effect of the discrepancy vocabulary (estimators/model_effects.hpp)
/// starting at each onset on a grid over the recent window. An effect of size theta starting at
/// step k0 adds theta g(k) to the innovations, with the signature g from
///     e-(k) = A_D(k) e+(k-1) + Phi(k) u(k),   g(k) = C e-(k) + m(k),   e+(k) = e-(k) - K(k) g(k)
/// (u: the effect's heat per unit size, m: its offset on the reading). Then
///     theta^ = sum g nu / S / sum g^2 / S,   l = (sum g nu / S)^2 / sum g^2 / S,
/// and the effect and onset of largest l are named (onsets every step over the last NIS window,
/// every `fit_onset_step_s` before). A reading bit-identical over many samples
/// while the model moves is a stuck sensor. Sensor effects (offset, stuck) are reported as
/// `kSensorFaultSuspected`, the rest as `kPlantChange`: the sensor alarm is not decided here.
///
/// With a magnet reading (the magnet temperature from the flux, of `magnet_node`) the fit has a
/// second channel: the reading less the filter's estimate of that node is theta e+(k) of the
/// node plus the reading's bias and noise. The bias is slow, so it is taken as one unknown
/// constant over the window (removed by the channel's mean, pre-onset samples included), and
/// one sample per `magnet_period_s` enters with sd `magnet_sd_K`; the channel adds to both sums
/// of theta^ and l. The frame's innovations (sd 0.06 K) outweigh it in l, so it also vetoes: an
/// effect and onset whose fitted size leaves the magnet samples a sum of squared residuals above
/// the chi-square quantile (samples - 1 degrees of freedom, `magnet_veto_probability`) is not
/// named while another is not vetoed. The reading is not fused into the filter: the detection
/// stays the frame's.
///
/// Pure library: time enters as an argument; no I/O. Allocates at construction; Step() does not
/// allocate once the operating point is steady; the naming fit (at detection and then every
/// `refit_period_s` while the test fails) may (matrix exponentials).

#include <Eigen/Dense>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "estimators/frame_sensor_model.hpp"
#include "estimators/kalman_filter.hpp"
#include "estimators/thermal_discretisation.hpp"
#include "estimators/thermal_model.hpp"

namespace pumptherm::estimators {

/// Codes published on CAN (pumptherm.dbc MismatchState) and LCM; do not renumber.
enum class MismatchState : std::uint8_t {
  kConsistent = 0,            ///< the nominal model explains the measurements
  kLearning = 1,              ///< too early to say (start, settling)
  kPlantChange = 2,           ///< the model is wrong: the plant changed (effect named)
  kSensorFaultSuspected = 3,  ///< the reading, not the plant, changed (offset, jump, stuck)
  kUnexplained = 4,           ///< the model is wrong; too little data yet to name the effect
};

/// Effect codes (pumptherm.dbc MismatchEffect); do not renumber. Names follow the discrepancy
/// vocabulary where it has the effect; `unmeasured_ambient` (a boundary the sensors do not see)
/// and `loss_scale` (every loss scaled alike) are not in it.
enum class MismatchEffect : std::uint8_t {
  kNone = 0,
  kFrameAmbientResistance = 1,  ///< value: resistance scale (x4 = cooling lost)
  kRotorLoss = 2,               ///< value: extra rotor heat, W
  kLossScale = 3,               ///< value: loss scale (1.4 = 40 % more)
  kUnmeasuredAmbient = 4,       ///< value: boundary temperature offset, K
  kSensorOffset = 5,            ///< value: offset of the reading, K
  kSensorStuck = 6,             ///< value: the frozen reading, degC
  kSensorLag = 7,               ///< value: the sensor's lag the readings fit, s
};
inline constexpr int kMismatchEffectCount = 8;

const char* MismatchStateName(MismatchState state);
/// Vocabulary name ("frame_ambient_resistance", ...).
const char* MismatchEffectName(MismatchEffect effect);

struct MismatchDetectorConfig {
  std::string measured_node = "frame";
  std::string rotor_node = "rotor";  ///< node of the rotor-loss hypothesis (absent: not tried)
  double measurement_sd_K = 0.06;    ///< white noise and quantisation of the reading
  double sensor_lag_s = 0.0;         ///< first-order lag of the sensor (0 = none)
  double sensor_offset_sd_K = 0.5;   ///< a priori calibration offset of the sensor
  /// Process noise of the nominal filter, K per sqrt(s): small, the model is believed.
  double process_sd_K = 0.005;
  double initial_sd_K = 20.0;  ///< as VirtualSensorConfig
  double initial_spread_sd_K = 5.0;
  double window_s = 60.0;                 ///< NIS window
  double false_alarm_probability = 1e-7;  ///< per window test: sets the chi-square threshold
  double settle_s = 300.0;                ///< no verdict before this long after Initialise
  double clear_after_s = 600.0;           ///< the test passing this long clears a finding
  double fit_window_s = 1200.0;           ///< history kept for naming
  double fit_onset_step_s = 20.0;         ///< onset grid of the naming fit
  /// When positive, the unmeasured ambient is also fitted as a linear rise to its size over this
  /// long. Off (0, the step only): a ramp names an ambient rise of about its own duration right
  /// and no other, and makes extra rotor heat be named an ambient rise first (docs/
  /// virtual-sensor.md, "Model mismatch").
  double ambient_ramp_s = 0.0;
  double refit_period_s = 60.0;  ///< refit while the test fails
  double name_after_s = 60.0;    ///< data after the detection before the first naming fit
  int stuck_samples = 60;        ///< identical readings that make a stuck sensor
  /// Node the magnet reading measures (empty or absent: no magnet channel in the naming fit).
  std::string magnet_node;
  /// Sd of one magnet sample about its window mean: the slow error of the flux (the demo's
  /// magnet temperature was 1.3-1.7 K off; the fault matrix emulates a 2 K bias).
  double magnet_sd_K = 2.0;
  double magnet_period_s = 10.0;          ///< one magnet sample per this period enters the fit
  double magnet_veto_probability = 1e-3;  ///< of a right effect being vetoed, per fit
  /// The sensor-lag hypothesis is named only for a fitted lag at least this many times longer
  /// (or shorter) than `sensor_lag_s`: closer, a lag is not told from the other effects' misfit.
  double lag_min_ratio = 1.5;
  /// With no lag configured (sensor_lag_s 0), a fitted lag shorter than this is none.
  double lag_min_s = 5.0;
  /// The fitted lag is named only while the history's NIS with it stays within its chi-square
  /// quantile at this upper probability (the lag explains the readings, not a part of them).
  double lag_fit_probability = 1e-3;
};

/// The detector's verdict.
struct MismatchFinding {
  MismatchState state = MismatchState::kLearning;
  MismatchEffect effect = MismatchEffect::kNone;
  double value = std::numeric_limits<double>::quiet_NaN();       ///< size, unit per effect
  double onset_s = std::numeric_limits<double>::quiet_NaN();     ///< fitted start of the effect
  double detected_s = std::numeric_limits<double>::quiet_NaN();  ///< when the test failed
  double window_nis = 0.0;                                       ///< sum of the last W NIS
  double threshold = 0.0;                                        ///< its chi-square quantile
  double likelihood_ratio = 0.0;                                 ///< l of the named effect
  double runner_up_ratio = 0.0;  ///< l of the best other effect (close to l: hard to tell apart)
  MismatchEffect runner_up = MismatchEffect::kNone;
  bool operator==(const MismatchFinding&) const = default;
};

/// "frame-to-ambient resistance x3.8 (cooling lost)" and the like; "consistent", "learning".
std::string DescribeFinding(const MismatchFinding& finding);

/// The (1 - p) quantile of chi-square with `dof` degrees of freedom (Wilson and Hilferty, "The
/// distribution of chi-square", PNAS 17(12), 1931: (x/k)^(1/3) is near normal).
double ChiSquareQuantile(double dof, double p_upper);

class MismatchDetector {
 public:
  /// Keeps a reference to `model`. Throws std::invalid_argument naming an unknown measured node
  /// or a non-positive setting.
  MismatchDetector(const ThermalModel& model, MismatchDetectorConfig config);

  /// Starts from every node (and the sensor) at `x0_degC` at time `now_s`.
  void Initialise(double x0_degC, double now_s);

  /// One period `dt_s` with `inputs` held, ending at `now_s`, reading `measured_degC` (NaN = no
  /// reading) and, for the naming fit only, the magnet reading `magnet_degC` of `magnet_node`
  /// (NaN = none). A period that is not positive and finite, or inputs the model cannot take,
  /// refuse the step: nothing changes, it is counted (refused_steps()), nothing is thrown.
  const MismatchFinding& Step(const ThermalInputs& inputs, double dt_s, double measured_degC,
                              double now_s,
                              double magnet_degC = std::numeric_limits<double>::quiet_NaN());

  const MismatchFinding& Finding() const { return finding_; }
  /// Takes `lag_s` (> 0) as the sensor's lag from now, as the estimator's filter does once the
  /// lag is named: the NIS window starts afresh, and the verdict stands until it is full again.
  /// False, nothing changed, for a sensor configured without a lag.
  bool AdoptSensorLag(double lag_s);
  /// The nominal filter's node estimates (n) and sensor offset, for reports and tests.
  Eigen::VectorXd Nodes_degC() const { return filter_.State().head(n_); }
  double SensorOffset_K() const { return filter_.State()(bias_); }
  int StateCount() const { return n_aug_; }
  /// Steps refused so far (Step()).
  std::uint64_t refused_steps() const { return refused_steps_; }

 private:
  void Linearise(const ThermalInputs& in, const Eigen::VectorXd& x_aug);
  void Record(const ThermalInputs& in, double y, double now_s);
  /// The naming fit; never throws (FitNow() is the fit itself).
  void Fit(double now_s);
  void FitNow(double now_s);
  void FitOnsets(int window);
  /// The sensor-lag hypothesis: the lag that best fits the history (lag_fit_s_) and the NIS it
  /// removes against the configured one (lag_l_; -1: not named, too close to the configured).
  void FitLag(int oldest);
  /// The sum of the NIS over the history of the nominal filter re-run with the sensor's lag at
  /// `lag_s`, from the state at history slot `oldest`.
  double HistoryNis(double lag_s, int oldest);
  /// Names the effect of largest likelihood ratio over the fit's `onsets` columns.
  void Choose(int onsets, int oldest);
  bool Stuck(int* first) const;
  /// Adds the magnet channel's sums (de-meaned over the window) to fit_a_, fit_b_, and marks in
  /// fit_veto_ the columns whose fitted size the magnet samples contradict.
  void AddMagnetChannel(int columns, double sum_r, double sum_rr, int samples);
  /// Whether hypothesis `h` is a column of the linear naming fit.
  bool LinearColumn(int h) const;
  /// The ramp hypothesis's share of its size `since_onset_s` after its onset (0..1).
  double AmbientRamp(double since_onset_s) const;
  /// Heat per unit effect size of hypothesis h at `in`, with the pre-step state `x_aug`.
  void EffectForcing(int h, const ThermalInputs& in, const Eigen::VectorXd& x_aug,
                     double frame_degC, Eigen::VectorXd& u);

  const ThermalModel& model_;
  MismatchDetectorConfig config_;
  FrameSensorModel sensor_model_;
  std::uint64_t refused_steps_ = 0;
  int n_ = 0, n_aug_ = 0, lag_ = -1, bias_ = 0, sensor_ = 0, frame_ = 0, rotor_ = -1, magnet_ = -1;
  double threshold_ = 0.0;
  Eigen::VectorXd boundary_K_per_s_per_K_;  ///< d f / d T_boundary (n)
  ThermalLinearModel lin_, lin_block_, lin_zero_;
  ThermalDiscretiser discretiser_;
  Eigen::MatrixXd ad_, sp_, c_, sm_;
  Eigen::VectorXd bu_, y_, x_nodes_;
  KalmanFilter filter_;
  double start_s_ = 0.0, last_fit_s_ = 0.0, passing_since_s_ = 0.0;
  bool failing_ = false;
  // NIS window.
  std::vector<double> nis_;
  int nis_next_ = 0, nis_count_ = 0;
  double nis_sum_ = 0.0;
  // History for naming (ring buffers, `cap_` steps).
  int cap_ = 0, head_ = 0, size_ = 0;
  std::vector<ThermalInputs> h_in_;
  std::vector<double> h_dt_, h_y_, h_nu_, h_s_, h_t_;
  std::vector<double> h_m_,
      h_xm_;  ///< magnet reading, the filter's estimate of its node after the step
  Eigen::MatrixXd h_xpre_, h_k_;  ///< state before the step, gain (n_aug x cap)
  // Fit workspace.
  ThermalDiscretiser fit_disc_;
  ThermalLinearModel fit_lin_;
  std::vector<int> fit_onsets_;  ///< onset steps (chronological history index), ascending
  Eigen::MatrixXd fit_e_, fit_phiu_;
  Eigen::VectorXd fit_a_, fit_b_, fit_x_, fit_tmp_, fit_u_col_;
  Eigen::VectorXd fit_frame_unit_;      ///< the cooling column's response per kelvin of offset
  Eigen::VectorXd fit_onset_offset_K_;  ///< per onset: the sensor offset estimated before it
  Eigen::VectorXd fit_me_, fit_mee_, fit_mre_;  ///< magnet channel: sums of e, e^2, r e per column
  std::vector<char> fit_veto_;                  ///< per column: contradicted by the magnet
  // FitLag's re-run of the nominal filter, its sensor always with a lag state.
  KalmanFilter fit_filter_{0};
  std::vector<int> fit_map_;  ///< its states' sources in the filter's state
  ThermalLinearModel fit_lag_lin_;
  ThermalDiscretiser fit_lag_disc_{1e-3};
  Eigen::MatrixXd fit_ad_, fit_sp_, fit_c_, fit_p0_;
  Eigen::VectorXd fit_bu_, fit_x0_;
  bool refilling_ = false;  ///< the NIS window restarted by AdoptSensorLag, not full yet
  double lag_fit_s_ = std::numeric_limits<double>::quiet_NaN();
  double lag_l_ = -1.0;
  int lag_readings_ = 0;  ///< readings in the last HistoryNis
  MismatchFinding finding_;
};

}  // namespace pumptherm::estimators
