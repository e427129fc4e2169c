// The fixed-size Kalman filter for 11 states (kalman_filter_fixed/fixed_size.hpp).
#include "estimators/kalman_filter_fixed/fixed_size_impl.hpp"

namespace pumptherm::estimators::detail {
template struct FixedSize<11>;
}  // namespace pumptherm::estimators::detail
