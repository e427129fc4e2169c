#pragma once
/// Copper resistance against temperature, shared by both estimators.
///
/// Han, Xiong, Mao, Vacuum 169 (2019) 108935, eqs. 2-3:
///     Rs = R0 (1 + alpha (Ts - T0))        Ts = (Rs / R0 - 1) / alpha + T0
/// (Saheba et al. 2010, eq. 3, uses the same law with alpha = 0.00393 1/degC.)

namespace pumptherm::estimators {

/// Temperature coefficient of copper used by Han 2019, 1/K.
inline constexpr double kAlphaCuHan2019_per_K = 4.1e-3;
/// Temperature coefficient of copper used by Saheba 2010, 1/K.
inline constexpr double kAlphaCuSaheba2010_per_K = 3.93e-3;

/// Reference point of the linear copper law.
struct CopperLaw {
  double r0_ohm = 0.28;                        ///< resistance at t0_degC
  double t0_degC = 20.0;                       ///< reference temperature
  double alpha_per_K = kAlphaCuHan2019_per_K;  ///< temperature coefficient
};

/// Resistance at temperature `t_degC` (Han 2019 eq. 2).
double ResistanceAt(const CopperLaw& law, double t_degC) noexcept;

/// Temperature at which the resistance is `r_ohm` (Han 2019 eq. 3).
double TemperatureAt(const CopperLaw& law, double r_ohm) noexcept;

}  // namespace pumptherm::estimators
