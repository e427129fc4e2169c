#pragma once
/// `pumptherm clear-trip` over CAN: which route the daemon's configuration authorises for a
/// pump, the PUMP_CLEAR frame for it, and the alarm level in the gateway's GW_ALARM frames that
/// says whether the clear took. Pure functions: the command opens the socket.

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "daemon/config.hpp"
#include "protocol/can_frame.hpp"
#include "protocol/dbc.hpp"
#include "protocol/mapping.hpp"

namespace pumptherm::tools {

enum class ClearRoute { kLcm, kCan };

/// The route a clear takes, and on CAN the interface to send on.
struct ClearRouteChoice {
  ClearRoute route = ClearRoute::kLcm;
  std::string interface;
};

/// The route for pump `pump` of config `c`: `via` is "lcm", "can" or "auto". Auto takes LCM
/// when the configuration has an LCM URL and a gateway signing key (signed, answered), else CAN
/// when the pump's interface is in the pump's alarms.clear_can_interfaces. Throws InputError
/// naming the configuration file and the keys when the chosen (or any) route is not authorised.
ClearRouteChoice ChooseClearRoute(const daemon::DaemonConfig& c, const daemon::PumpConfig& pump,
                                  std::string_view via);

/// The PUMP_CLEAR frame (the mapping's alarm_clear signal set to 1) for the pump with `node_id`.
/// Throws InputError when the mapping has no alarm_clear or the node ID is above its limit.
protocol::CanFrame EncodeClearFrame(const protocol::Dbc& dbc,
                                    const protocol::SignalMapping& mapping, std::uint32_t node_id);

/// Alarm levels as GW_ALARM's AlarmLevel carries them.
enum class GatewayAlarmLevel { kNormal = 0, kWarning = 1, kTrip = 2 };

/// The alarm level in `frame` when it is the mapping's alarm_level message of the pump with
/// `node_id`; nullopt for any other frame, a short one, or the not-available value.
std::optional<GatewayAlarmLevel> AlarmLevelOf(const protocol::Dbc& dbc,
                                              const protocol::SignalMapping& mapping,
                                              std::uint32_t node_id,
                                              const protocol::CanFrame& frame);

/// What the GW_ALARM frames before and after a CAN clear say, for the operator.
struct CanClearOutcome {
  std::optional<GatewayAlarmLevel> before;  ///< last level seen before the clear was sent
  std::optional<GatewayAlarmLevel> after;   ///< last level seen once the gateway had time to act
};

/// One line for the operator and the exit code (0 the trip is gone, 1 not, or no answer).
std::pair<int, std::string> DescribeCanClear(const std::string& pump, const std::string& interface,
                                             const CanClearOutcome& o, double waited_s);

}  // namespace pumptherm::tools
