#pragma once
/// What the pump estimator is given for one thermal period: the drive quantities averaged over
/// it, the ages of the telemetry, and the resistance identifier's outputs at its end. The daemon
/// (daemon/pump.cpp) forms it from the frames; a tool from a recording or a CSV.

#include <Eigen/Dense>
#include <cstdint>
#include <limits>

#include "estimators/resistance_identifier.hpp"
#include "estimators/thermal_model.hpp"

namespace pumptherm::estimators {

/// The resistance identifier (ResistanceIdentifier, Han et al. 2019) as the readings see it at
/// the end of a period.
struct IdentifierOutput {
  ResistanceEstimate estimate;                  ///< status, Rs, psi_f, the winding from eq. 3
  Eigen::Matrix4d p = Eigen::Matrix4d::Zero();  ///< covariance of [Rs, dRs/dt, psi_f, dpsi_f/dt]
  /// Time since its last sample and since its last block update, s (NaN: none yet).
  double sample_age_s = std::numeric_limits<double>::quiet_NaN();
  double block_age_s = std::numeric_limits<double>::quiet_NaN();
};

/// The drive's dq quantities averaged over the period's paired samples (the voltage equation's
/// inputs; estimators/readings/voltage_reading.hpp).
struct DriveAverages {
  int samples = 0;  ///< paired samples in the period
  double id_A = std::numeric_limits<double>::quiet_NaN();
  double iq_A = std::numeric_limits<double>::quiet_NaN();
  double ud_V = std::numeric_limits<double>::quiet_NaN();
  double uq_V = std::numeric_limits<double>::quiet_NaN();
  double w_rad_per_s = std::numeric_limits<double>::quiet_NaN();  ///< electrical
  /// The sd of iq over the period's samples beyond their sample-to-sample noise, A: a load
  /// change inside the period.
  double iq_change_sd_A = std::numeric_limits<double>::quiet_NaN();
};

struct PumpPeriod {
  std::int64_t end_us = 0;  ///< the period's end (the pipeline's clock)
  double dt_s = 1.0;        ///< its length (one step over a long silence may be longer)
  /// The thermal model's inputs over the period: rms currents, mean mechanical speed, the
  /// latest ambient and coolant (held when no frame brought them).
  ThermalInputs inputs;
  /// Fast telemetry arrived in this period (else `inputs` are the last ones, held).
  bool fresh_inputs = false;
  /// The period's mean q current (signed), A; NaN without fast telemetry in it.
  double mean_iq_A = std::numeric_limits<double>::quiet_NaN();
  /// The latest ambient temperature heard, degC (NaN: none yet): where the filter starts when
  /// no frame reading has come.
  double ambient_degC = std::numeric_limits<double>::quiet_NaN();
  /// Age of the oldest kind of telemetry that has arrived at least once (fast frames, status)
  /// at the period's end, s; and of the fast frames alone (NaN: none yet).
  double telemetry_age_s = 0.0;
  double fast_age_s = std::numeric_limits<double>::quiet_NaN();
  IdentifierOutput identifier;
  DriveAverages drive;
};

}  // namespace pumptherm::estimators
