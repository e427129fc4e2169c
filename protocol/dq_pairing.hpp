#pragma once
/// Pairing of a drive's two fast telemetry halves into one dq sample: the current frame (id,
/// iq) and the voltage frame (ud, uq), each with the rolling counter it carries (NaN: none).
/// Two halves within the pairing window of each other whose counters are equal (or either of
/// which carries none) make one sample at the later half's time; a half whose partner never
/// came is counted as unpaired when the next of its kind replaces it. The daemon and the
/// recording reader of the tools pair through this one class.
///
/// Pure: no I/O, no allocation.

#include <cstdint>
#include <limits>

namespace pumptherm::protocol {

/// One paired sample.
struct DqPair {
  std::int64_t t_us = -1;  ///< the later half's time
  double id_A = std::numeric_limits<double>::quiet_NaN();
  double iq_A = std::numeric_limits<double>::quiet_NaN();
  double ud_V = std::numeric_limits<double>::quiet_NaN();
  double uq_V = std::numeric_limits<double>::quiet_NaN();
};

class DqPairing {
 public:
  /// Largest gap between the two halves of one sample by default, us (two frames of one 10 ms
  /// telemetry cycle arrive well within it; the next cycle's do not).
  static constexpr std::int64_t kDefaultWindowUs = 50'000;
  explicit DqPairing(std::int64_t window_us = kDefaultWindowUs) : window_us_(window_us) {}

  /// A current half at `t_us`. Returns true, with the sample in `out`, when it completes one.
  bool OnCurrents(std::int64_t t_us, double id_A, double iq_A, double counter, DqPair& out) {
    if (currents_.t_us >= 0) ++unpaired_;  // its voltages never came
    currents_ = Half{t_us, id_A, iq_A, counter};
    return TryPair(out);
  }
  /// A voltage half at `t_us`. Returns true, with the sample in `out`, when it completes one.
  bool OnVoltages(std::int64_t t_us, double ud_V, double uq_V, double counter, DqPair& out) {
    if (voltages_.t_us >= 0) ++unpaired_;  // its currents never came
    voltages_ = Half{t_us, ud_V, uq_V, counter};
    return TryPair(out);
  }
  /// Halves whose partner never came.
  std::uint64_t unpaired() const { return unpaired_; }

 private:
  struct Half {
    std::int64_t t_us = -1;
    double a = std::numeric_limits<double>::quiet_NaN();
    double b = std::numeric_limits<double>::quiet_NaN();
    double counter = std::numeric_limits<double>::quiet_NaN();
  };
  bool TryPair(DqPair& out) {
    if (currents_.t_us < 0 || voltages_.t_us < 0) return false;
    const std::int64_t gap_us = currents_.t_us - voltages_.t_us;
    const bool near = (gap_us < 0 ? -gap_us : gap_us) <= window_us_;
    const bool same = currents_.counter == voltages_.counter ||
                      currents_.counter != currents_.counter ||
                      voltages_.counter != voltages_.counter;  // NaN: no counter
    if (!near || !same) return false;  // the older half waits to be replaced (counted unpaired)
    out.t_us = currents_.t_us > voltages_.t_us ? currents_.t_us : voltages_.t_us;
    out.id_A = currents_.a;
    out.iq_A = currents_.b;
    out.ud_V = voltages_.a;
    out.uq_V = voltages_.b;
    currents_ = Half{};
    voltages_ = Half{};
    return true;
  }

  std::int64_t window_us_;
  Half currents_, voltages_;
  std::uint64_t unpaired_ = 0;
};

}  // namespace pumptherm::protocol
