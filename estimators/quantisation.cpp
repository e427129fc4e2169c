#include "estimators/quantisation.hpp"

#include <cmath>
#include <numbers>

namespace pumptherm::estimators {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr int kTerms = 6;

// sum_k (-1)^(k+1)/k damping_k sin(2 pi k phase), the bracket of the bias formula.
template <typename Damping>
double Series(double mean, double step, Damping damping) noexcept {
  // Reduce the argument to one period first: sin(2 pi k mean / step) of a mean of 40 V on a
  // 23 mV step would otherwise lose digits.
  const double phase = mean / step - std::floor(mean / step);
  double sum = 0.0;
  for (int k = 1; k <= kTerms; ++k) {
    const double sign = (k % 2 == 1) ? 1.0 : -1.0;
    sum += sign / k * damping(k) * std::sin(2.0 * kPi * k * phase);
  }
  return sum;
}

}  // namespace

double QuantisedMeanBias(double mean, double noise_variance, double step) noexcept {
  if (!(step > 0.0) || !std::isfinite(mean) || !std::isfinite(noise_variance) ||
      !std::isfinite(step)) {
    return 0.0;
  }
  const double var = noise_variance > 0.0 ? noise_variance : 0.0;
  const double c1 = 2.0 * kPi * kPi / (step * step);
  return -step / kPi * Series(mean, step, [&](int k) { return std::exp(-c1 * k * k * var); });
}

double CorrectQuantisedMean(double sample_mean, double sample_variance, int n,
                            double step) noexcept {
  if (!(step > 0.0) || n < 2 || !std::isfinite(sample_mean) || !std::isfinite(sample_variance) ||
      !std::isfinite(step)) {
    return sample_mean;
  }
  const double sheppard = step * step / 12.0;
  double noise_variance = sample_variance - sheppard;
  const double min_sd = kMinCorrectableNoise_steps * step;
  if (!(noise_variance >= min_sd * min_sd)) return sample_mean;
  const double c1 = 2.0 * kPi * kPi / (step * step);
  const double dof = n - 1.0;
  double mean = sample_mean;
  double bias = 0.0;
  for (int i = 0; i < 3; ++i) {
    // The variance of the quantised samples is not exactly sigma^2 + step^2/12: its leading
    // periodic term is -(4 sigma^2 + step^2/pi^2) exp(-c1 sigma^2) cos(2 pi mu/step) (from the
    // same Fourier series, with Stein's lemma for E[n sin(a(mu + n))]), and the squared bias
    // of the mean comes off it.
    const double g1 = std::exp(-c1 * noise_variance);
    noise_variance = sample_variance - sheppard + bias * bias +
                     (4.0 * noise_variance + step * step / (kPi * kPi)) * g1 *
                         std::cos(2.0 * kPi * (mean / step - std::floor(mean / step)));
    if (!(noise_variance >= min_sd * min_sd)) return sample_mean;
    // exp(-c sigma^2) from a sample variance s^2 of n values is biased up (Jensen): with
    // s^2 ~ sigma_q^2 chi^2_(n-1)/(n-1), E[exp(-c s^2)] = exp(-c sigma_q^2) J,
    // ln J = c sigma_q^2 - (n-1)/2 ln(1 + 2 c sigma_q^2/(n-1)); dividing by J removes it.
    bias = -step / kPi * Series(mean, step, [&](int k) {
      const double c = c1 * k * k;
      const double ln_j =
          c * sample_variance - 0.5 * dof * std::log1p(2.0 * c * sample_variance / dof);
      return std::exp(-c * noise_variance - ln_j);
    });
    mean = sample_mean - bias;
  }
  return mean;
}

}  // namespace pumptherm::estimators
