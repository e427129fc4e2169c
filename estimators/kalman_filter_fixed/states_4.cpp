// The fixed-size Kalman filter for 4 states (kalman_filter_fixed/fixed_size.hpp).
#include "estimators/kalman_filter_fixed/fixed_size_impl.hpp"

namespace pumptherm::estimators::detail {
template struct FixedSize<4>;
}  // namespace pumptherm::estimators::detail
