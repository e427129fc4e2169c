// A one-node thermal model with a closed-form answer, for tests of what runs on the network.
#pragma once

namespace pumptherm::estimators::test {

// One node to ambient: C dT/dt = P - (T - Ta) / R with P = 2 W per A^2 of iq, C = 100 J/K,
// R = 1 K/W, so T(t) = Ta + P R + (T0 - Ta - P R) e^(-t / (R C)).
inline constexpr const char* kOneNode = R"(
[model]
name = "one"
[[node]]
name = "n"
capacity_J_per_K = 100
[[edge]]
between = ["n", "ambient"]
resistance_K_per_W = 1.0
[[loss]]
name = "joule"
power_W = "2.0 * iq_A^2"
shares = { n = 1 }
)";

}  // namespace pumptherm::estimators::test
