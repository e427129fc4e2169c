#pragma once
/// One pump's frame path: the decoded telemetry in SI units is paired (protocol/dq_pairing.hpp)
/// and fed to the resistance identifier at telemetry rate, averaged over each thermal period
/// (timed by the frames' timestamps), and handed to the pump estimator
/// (estimators/pump_estimator.hpp) once per period, which does everything from there to the
/// alarms. No I/O here: the gateway decodes frames and publishes what this produces.

#include <Eigen/Dense>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "daemon/config.hpp"
#include "estimators/motor.hpp"
#include "estimators/pump_estimator.hpp"
#include "estimators/resistance_identifier.hpp"
#include "estimators/thermal_model.hpp"
#include "protocol/dq_pairing.hpp"

namespace pumptherm::daemon {

inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
inline constexpr double kInf = std::numeric_limits<double>::infinity();
using estimators::kMaxEstimate_degC;
using estimators::kMinEstimate_degC;

/// Counters of one pump's inputs (what was dropped is counted, never silent).
struct PumpCounters {
  std::uint64_t fast_frames = 0;
  std::uint64_t status_frames = 0;
  std::uint64_t samples = 0;          ///< paired current+voltage samples identified
  std::uint64_t unpaired = 0;         ///< half-samples whose partner never came
  std::uint64_t lost_frames = 0;      ///< gaps in the rolling counter
  std::uint64_t rejected_values = 0;  ///< NaN/Inf or out-of-range decoded values, refused steps
  std::uint64_t thermal_steps = 0;
  std::uint64_t filter_resets = 0;  ///< estimate left [kMinEstimate_degC, kMaxEstimate_degC]
};

/// Everything published about one pump at one moment.
using PumpSnapshot = estimators::PumpEstimate;

/// Saved state of one pump (the state store writes it; docs/daemon.md "State"): the estimator's
/// and the identifier's.
struct PumpSavedState : estimators::PumpEstimatorState {
  estimators::ResistanceIdentifierState resistance;
};

/// The estimator's settings from a pump's configuration.
estimators::PumpEstimatorConfig EstimatorConfig(const PumpConfig& config, double thermal_period_s);

class Pump {
 public:
  /// Throws std::invalid_argument naming the pump, its line and the problem (unknown measured
  /// node, a level for a node the model lacks, bad estimator settings).
  Pump(const PumpConfig& config, const estimators::MotorDescription& motor,
       std::shared_ptr<const estimators::ThermalModel> model, double thermal_period_s);
  /// How many numbers the observer's saved whole state has beyond its nodes (0: the nodes
  /// alone are its state, none are saved apart).
  int ObserverStateCount() const {
    const auto& o = estimator_->observer();
    return o.StateCount() > o.NodeCount() ? o.StateCount() : 0;
  }

  const PumpConfig& config() const { return config_; }
  /// Whether the disturbance-state filter is published (the configuration, resolved per model).
  bool disturbance_states() const { return estimator_->disturbance_states(); }
  const estimators::ResistanceIdentifier& identifier() const { return identifier_; }
  const estimators::ThermalModel& model() const { return *model_; }
  const estimators::MotorDescription& motor() const { return motor_; }
  const estimators::PumpEstimator& estimator() const { return *estimator_; }
  /// Every active alarm condition, most severe first, into `out`: no allocation once `out` has
  /// held as many (the gateway's LCM path).
  void ActiveConditions(std::vector<estimators::AlarmCondition>& out) const {
    estimator_->ActiveConditions(out);
  }

  /// Fast telemetry halves (NaN for what the mapping does not carry), paired into one
  /// identifier sample (protocol::DqPairing).
  void OnCurrents(std::int64_t t_us, double id_A, double iq_A, double w_e_rad_per_s,
                  double counter);
  void OnVoltages(std::int64_t t_us, double ud_V, double uq_V, double counter);
  /// Slow status (NaN for what is not mapped or not available).
  void OnStatus(std::int64_t t_us, double speed_rpm, double drive_state, double frame_degC,
                double ambient_degC);

  /// Runs every thermal step whose period ended at or before `t_us`. Returns true when the
  /// alarm state changed.
  bool Advance(std::int64_t t_us);

  /// Clears latched trips (from an accepted clear command). Returns true if one was latched.
  bool ClearTrips() { return estimator_->ClearTrips(); }
  /// Clears the latched trip of one alarm node (LatchIndex()). Returns true if it was latched.
  bool ClearTrip(int node) { return estimator_->ClearTrip(node); }
  /// The alarm monitor's index of alarm node `name` (a model node, "sensor",
  /// "winding_resistance", "safety_state_lost"), or nullopt for a name this pump lacks.
  std::optional<int> LatchIndex(const std::string& name) const {
    return estimator_->LatchIndex(name);
  }
  /// Latches the trip "safety state lost" at `now_us` (the gateway, at start, when the latched
  /// trips and clear counters saved could not be read); published at once.
  void LatchStateLost(std::int64_t now_us) { estimator_->LatchStateLost(now_us); }
  /// Evidence of a second sender on this pump's CAN IDs at `now_us`: a warning, published at once.
  void RaiseSecondSender(std::int64_t now_us) { estimator_->RaiseSecondSender(now_us); }

  const PumpSnapshot& snapshot() const { return estimator_->estimate(); }
  const PumpCounters& counters() const { return counters_; }
  /// Time of the last telemetry frame (fast or status), us; -1 before any.
  std::int64_t last_frame_us() const { return last_frame_us_; }
  /// Whether a frame was heard and the thermal steps run (false before the first frame).
  bool heard() const { return heard_; }
  /// For a pump never heard from: runs its alarms (once per thermal period) with every input
  /// `t_us - since_us` old, so that after `stale_after_s` it raises stale telemetry like a pump
  /// that fell silent. Returns whether the alarm changed. No effect once a frame was heard.
  bool CheckNeverHeard(std::int64_t since_us, std::int64_t t_us);
  /// The earliest time (us) at which Advance or CheckNeverHeard has work: the end of the next
  /// thermal period; INT64_MIN when due at once (a first frame not yet advanced to, or a pump
  /// never heard from whose silence is not yet timed). Before it, both change nothing.
  std::int64_t NextDueUs() const;

  PumpSavedState Save() const;
  /// Continues from `state` saved at state.time_us, aged to `now_us` (PumpEstimator::Restore),
  /// the identifier restored too. Returns false (nothing changes) when the state does not fit
  /// this pump or is damaged.
  bool Restore(const PumpSavedState& state, std::int64_t now_us);
  /// Latches again only the trips of `state` (PumpEstimator::RestoreLatchedTrips).
  bool RestoreLatchedTrips(const PumpSavedState& state, std::int64_t now_us) {
    return estimator_->RestoreLatchedTrips(state, now_us);
  }

 private:
  void ThermalStep(std::int64_t end_us, double dt_s);
  /// The period's inputs into `period` (mean squared currents, mean speed, the latest ambient;
  /// held when no fast frame came); false while nothing is known to step on.
  bool PeriodInputs(estimators::PumpPeriod& period);
  void Identify(const protocol::DqPair& pair);
  void NoteFastFrame(std::int64_t t_us);
  void CountLostFrames(double counter);
  /// The latest of two frame times (`last_us`, the one before it `previous_us`) not after `t_us`.
  static std::int64_t LastAtOrBefore(std::int64_t last_us, std::int64_t previous_us,
                                     std::int64_t t_us);
  /// Age of the oldest input kind that has arrived at least once (fast frames, status), s.
  double TelemetryAge_s(std::int64_t t_us) const;
  /// The identifier as the readings see it at `t_us`.
  estimators::IdentifierOutput IdentifierAt(std::int64_t t_us) const;
  void SyncCounters();

  PumpConfig config_;
  std::shared_ptr<const estimators::ThermalModel> model_;
  estimators::MotorDescription motor_;
  double period_s_;
  std::int64_t period_us_;
  estimators::ResistanceIdentifier identifier_;
  std::unique_ptr<estimators::PumpEstimator> estimator_;
  std::uint64_t identifier_blocks_ = 0;  // block updates seen, to time the flux's freshness
  std::int64_t flux_block_us_ = -1;      // time of the identifier's last block update
  PumpCounters counters_;

  protocol::DqPairing pairing_;
  double last_counter_ = kNaN;
  std::int64_t last_sample_us_ = -1;
  double w_e_rad_per_s_ = kNaN;  // latest electrical speed (fast frame or status)

  // Status values.
  double ambient_degC_ = kNaN;
  double speed_rpm_ = kNaN;
  std::int64_t last_frame_us_ = -1;
  std::int64_t last_fast_us_ = -1;
  std::int64_t previous_fast_us_ = -1;  // the fast frame time before last_fast_us_
  std::int64_t last_status_us_ = -1;
  std::int64_t previous_status_us_ = -1;

  // Inputs averaged over the current thermal period.
  double sum_id2_ = 0.0, sum_iq2_ = 0.0, sum_speed_ = 0.0, sum_iq_ = 0.0;
  int n_inputs_ = 0;
  /// The period's paired samples, for the voltage equation (estimators::DriveAverages).
  struct DriveSums {
    int n = 0;
    double id = 0.0, iq = 0.0, iq2 = 0.0, ud = 0.0, uq = 0.0, w = 0.0;
    /// Successive samples' squared iq differences and their count, and the last sample's iq.
    double diq2 = 0.0;
    int differences = 0;
    double last_iq = std::numeric_limits<double>::quiet_NaN();
  };
  DriveSums drive_;
  /// The period's drive averages (and the sums back to zero).
  estimators::DriveAverages TakeDriveAverages();
  estimators::ThermalInputs held_inputs_;
  bool have_inputs_ = false;
  std::int64_t next_step_us_ = -1;
  bool heard_ = false;  // a frame was heard (Advance runs thermal steps from then on)
};

}  // namespace pumptherm::daemon
