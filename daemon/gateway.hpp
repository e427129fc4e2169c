#pragma once
/// The gateway: frames in, per-pump estimation, frames and LCM messages out. It does not know
/// where frames come from or go (live sockets or log files: OutputSink) nor what time it is
/// (frame timestamps and Advance(now) bring time in), which is what makes an offline run of a
/// recording equal a live run of it (docs/architecture.md, "Data flow, from a frame to an alarm").

#include <cstdint>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include "daemon/alarm_clear_auth.hpp"
#include "daemon/can_plausibility.hpp"
#include "daemon/clear_audit.hpp"
#include "daemon/config.hpp"
#include "daemon/frame_counter.hpp"
#include "daemon/log.hpp"
#include "daemon/published_fields.hpp"
#include "daemon/pump.hpp"
#include "daemon/safety_state.hpp"
#include "protocol/codec.hpp"
#include "protocol/dbc.hpp"
#include "protocol/mapping.hpp"
#include "pumptherm/alarm_t.hpp"
#include "pumptherm/gateway_health_t.hpp"
#include "pumptherm/telemetry_t.hpp"
#include "pumptherm/temperatures_t.hpp"

namespace pumptherm::daemon {

/// Where the gateway's output goes.
class OutputSink {
 public:
  virtual ~OutputSink() = default;
  /// A frame for interface `iface` (FrameCounter index) at time `time_us`.
  virtual void SendFrame(std::size_t iface, std::int64_t time_us,
                         const protocol::CanFrame& frame) = 0;
  /// An encoded LCM message for `channel`. Returns false when it could not be sent (counted).
  virtual bool PublishLcm(const std::string& channel, std::int64_t time_us,
                          const std::vector<std::uint8_t>& bytes) = 0;
};

/// Gateway-wide counters beyond the per-interface ones.
/// The MQTT sink's figures for the health message (gateway_health_t), handed in by the loop
/// that runs the sink; all zero without one.
struct MqttHealth {
  bool enabled = false;
  bool connected = false;
  std::uint64_t dropped = 0;         ///< data steps dropped: its queue was full
  std::uint64_t alarms_dropped = 0;  ///< alarm transitions dropped: their queue was full
};

struct GatewayCounters {
  std::uint64_t rx_unknown_id = 0;  ///< frames whose ID no configured pump uses
  /// Of those, frames of a mapped input message for a node ID no pump on that interface has
  /// (a pump configured with the wrong node_id, or an unconfigured pump); warned about.
  std::uint64_t rx_unconfigured_node = 0;
  std::uint64_t rx_bad_length = 0;  ///< frames shorter than their message: rejected
  std::uint64_t tx_saturated = 0;   ///< output values clamped to a signal's range
  std::uint64_t lcm_published = 0;
  std::uint64_t lcm_failed = 0;
  std::uint64_t clears_accepted = 0;
  std::uint64_t clears_refused = 0;  ///< every refused clear, whatever the reason
  std::uint64_t clears_unauthenticated =
      0;  ///< of those: LCM clears without a valid code (or undecodable)
  std::uint64_t clears_rate_limited = 0;  ///< PUMP_CLEAR repeats within 2 s: ignored
  std::uint64_t trip_latches = 0;         ///< trips latched (the live loop saves the state at once)
  /// Frames that a second sender on the bus must have sent (CanPlausibility): the gateway's own
  /// output IDs from elsewhere, a pump's message too fast, a broken rolling counter.
  std::uint64_t rx_second_sender = 0;
};

class Gateway {
 public:
  /// Builds every pump from `config`: reads the DBC, the mapping, motor descriptions and thermal
  /// models it names. Throws ConfigError naming the config file, the line and the key (or the
  /// referenced file and its own position) for anything that does not fit.
  explicit Gateway(const DaemonConfig& config);

  /// Index of the interface called `name` (registered on first use; routes frames to the pumps
  /// configured on it).
  std::size_t Interface(std::string_view name);

  /// One received frame: counted, decoded through the DBC and the mapping, fed to its pump.
  /// No allocation in steady state, never throws.
  void OnFrame(std::size_t iface, const protocol::TimedFrame& frame);

  /// Brings every pump up to time `now_us` (thermal steps, alarms, stale checks), and sends the
  /// outputs that are due through `sink`. Live: called from the loop's timer and after frames;
  /// offline: after each frame. Only the pumps with something due are visited; before
  /// NextDueUs() it returns at once.
  void Advance(std::int64_t now_us, OutputSink& sink);

  /// The earliest pipeline time (us) at which Advance has work: a thermal step, an output
  /// frame or LCM message, the health message, a pump's silence to time, or (INT64_MIN) at once
  /// after a frame or command that changes what is due. An Advance before it changes nothing.
  std::int64_t NextDueUs() const { return next_due_us_; }

  /// An alarm-clear command for pump `pump` from `source` (an LCM source name, or
  /// "can:<interface>"). Accepted only from configured sources; every attempt is logged.
  /// Returns true when accepted.
  bool Clear(const std::string& pump, const std::string& source, const std::string& comment);

  /// An LCM alarm_clear_t received at gateway time `now_us` (us since the Unix epoch); nullptr
  /// when the bytes did not decode as one. Accepted only for this gateway, signed by a listed
  /// operator key that is not revoked, inside the time window, with a new counter
  /// (ClearAuthenticator::Check), and for a node that is latched (or every latched trip); the
  /// new counter and latches are made durable (SetSafetyCommit) before the trip is cleared and
  /// the answer sent. Every attempt is logged (rate-limited, with structured fields) and
  /// counted; only a command whose signature holds is answered, on
  /// <prefix>/<pump>/ALARM_CLEAR_REPLY through `sink`. Returns true when accepted.
  bool ClearFromLcm(const pumptherm::alarm_clear_t* m, std::int64_t now_us, OutputSink& sink);

  /// Loads the gateway's signing key, the operators' public keys and (migration only) the
  /// shared key named by the configuration; without a signing key every LCM clear is refused
  /// (a warning when operators are listed). Throws ConfigError.
  void LoadClearKeys(const std::string& credentials_dir);
  /// Sets the gateway's signing key directly (tests; LoadClearKeys reads the configured file).
  void SetGatewayKey(const SigningKey& key) { clear_auth_.SetGatewayKey(key); }
  /// Sets the shared key of the earlier scheme directly (tests).
  void SetSharedKey(const ClearKey& key) {
    clear_auth_.SetSharedKey(key, config_.alarms.clear_lcm_sources);
  }
  const ClearAuthenticator& clear_auth() const { return clear_auth_; }

  /// Makes a safety state durable: `text` (FormatSafetyState) written and synced before the
  /// call returns true; false with the reason in `*error`. The live loop writes safety.toml;
  /// without one (offline, tests) nothing is written and every commit succeeds.
  using SafetyCommit = std::function<bool(const std::string& text, std::string* error)>;
  void SetSafetyCommit(SafetyCommit commit) { safety_commit_ = std::move(commit); }
  /// The safety state now: every pump's latched trips and the clear counters.
  SafetyState CollectSafetyState() const;
  /// Commits CollectSafetyState() (after a trip latched). Returns false when it failed (logged).
  bool CommitSafetyState();
  /// Takes the safety state read at start (after RestoreState): each pump's latched trips become
  /// exactly those saved (a clear after the last estimator save stays cleared), the counters
  /// are merged. A pump whose saved latches name a node it lacks latches "safety state lost"
  /// instead (warned about). `now_us`: pipeline time.
  void ApplySafetyState(const SafetyState& s, std::int64_t now_us);
  /// The safety state could not be read at start (`why`: damaged, missing): no command signed
  /// up to `wall_now_us` (the start) is accepted, so a command recorded before cannot replay; with
  /// gateway.lost_safety_state = "latch" every pump latches the trip "safety state lost". Logs
  /// why. `now_us`: pipeline time.
  void SafetyStateLost(const std::string& why, std::int64_t now_us, std::int64_t wall_now_us);
  /// No clear command signed up to `wall_us` is accepted (a start without saved counters).
  void RefuseClearsSignedUpTo(std::int64_t wall_us) { clear_auth_.RefuseSignedUpTo(wall_us); }
  /// Writes the summary lines of refused clears not logged yet, one per source (at stop).
  void FlushClearAudit();

  FrameCounter& counter() { return counter_; }
  const FrameCounter& counter() const { return counter_; }
  const GatewayCounters& counters() const { return counters_; }
  /// The MQTT sink's figures that the next health messages carry.
  void SetMqttHealth(const MqttHealth& h) { mqtt_health_ = h; }
  const std::vector<std::unique_ptr<Pump>>& pumps() const { return pumps_; }
  const DaemonConfig& config() const { return config_; }

  /// Wall clock minus the pipeline's clock (us). The pipeline's time (frame stamps, Advance)
  /// measures elapsed time: the log's stamps offline (offset 0), CLOCK_MONOTONIC live, where the
  /// loop sets this before each Advance. Wall time only labels: LCM utime fields and the saved
  /// state's times, which outlive a boot.
  void SetWallClockOffset(std::int64_t wall_minus_pipeline_us) {
    wall_offset_us_ = wall_minus_pipeline_us;
  }

  /// Saved state of every pump as text (TOML; docs/daemon.md "State").
  std::string SaveState() const;
  /// Restores the pumps found in `text` (saved by SaveState), aged to `now_us` (pipeline time;
  /// the saved wall times are mapped with SetWallClockOffset's offset). Returns the
  /// number of pumps restored; `warning` says what was ignored and why. Never throws.
  int RestoreState(const std::string& text, std::int64_t now_us, std::string* warning);

  /// One line for systemd's STATUS=: frames, pumps, alarms, drops.
  std::string StatusLine() const;
  /// A terminal table of the pumps: temperatures, resistance, alarm.
  std::string PumpTable() const;

  /// What pump `pump`'s published fields are read from, with what the pump alone knows (its
  /// estimate, its settings, the wall clock): for the LCM messages and the offline CSV.
  FieldSource Source(const Pump& pump) const;

  /// Encodes one LCM message of each kind for pump `p` (used by Advance and by tests).
  std::vector<std::uint8_t> EncodeTemperatures(const Pump& p) const;
  std::vector<std::uint8_t> EncodeTelemetry(std::size_t pump_index) const;
  std::vector<std::uint8_t> EncodeAlarm(const Pump& p) const;
  std::vector<std::uint8_t> EncodeHealth(std::int64_t now_us) const;

 private:
  /// Warns (at most once a minute per interface and node ID) about a frame of a mapped input
  /// message from a node ID that no pump on its interface has, naming the pumps of that
  /// interface not yet heard from: the likely ones with a wrong node_id.
  void WarnUnconfiguredNode(std::size_t iface, const protocol::TimedFrame& tf);
  struct InputSignal {
    protocol::MappingInput input;
    int signal_index;
    double scale, offset;
  };
  struct InputMessage {
    int message_index;
    std::vector<InputSignal> signals;
    bool currents = false, voltages = false, status = false, clear = false;
    double cycle_s = 0.0;          ///< the DBC's cycle time (0: none; not rate-checked)
    bool rolling_counter = false;  ///< carries the mapped rolling counter
  };
  /// The second-sender checks of one input message of one pump.
  struct InputChecks {
    RateCheck rate;
    CounterCheck counter;
  };
  enum class OutputSource : std::uint8_t { kField, kNode, kRollingCounter };
  struct OutputSignal {
    int signal_index;
    OutputSource source;
    const PublishedField* field;  // kField
    int state;                    // kNode
    double scale, offset;
  };
  struct OutputPlan {
    int message_index;
    std::int64_t period_us;
    std::int64_t next_due_us = -1;
    std::uint8_t counter = 0;
    std::vector<OutputSignal> signals;
    bool alarm = false;       // sent at once when the alarm changes
    bool node_table = false;  // node-indexed: each model node once per period, in turn
    int next_node = 0;        // node_table: the node the next frame carries
  };
  std::map<std::uint64_t, std::int64_t> unconfigured_warned_us_;  ///< (iface, node) -> last warning
  /// A due time that every time has reached: work at the next Advance.
  static constexpr std::int64_t kDueNow = std::numeric_limits<std::int64_t>::min();
  struct PumpIo {
    std::size_t iface = 0;          // FrameCounter index
    std::int64_t due_us = kDueNow;  // earliest time AdvancePump has work (PumpDueUs)
    std::vector<OutputPlan> outputs;
    std::int64_t next_lcm_us = -1;
    std::uint64_t alarm_changes_sent = 0;
    std::uint64_t mismatch_changes_logged = 0;
    std::uint64_t sensor_steps_logged = 0;
    std::uint64_t starts_logged = 0;
    std::uint64_t r0_changes_logged = 0;
    std::uint64_t magnet_law_logged = 0;
    std::uint64_t sensor_lag_logged = 0;
    // Latest decoded inputs, for telemetry_t.
    double inputs[protocol::kMappingInputCount];
    std::int64_t inputs_us = -1;
    std::int64_t status_us = -1;
    std::uint64_t frames_at_last_health = 0;
    std::int64_t last_health_us = -1;
    double frame_rate_Hz = 0.0;
    std::int64_t last_clear_us = -1;          // last clear command frame acted on
    std::uint16_t logged_active_reasons = 0;  // the active reasons the last alarm line showed
    bool clear_repeat_logged = false;         // a rate-limited repeat of it was logged
    bool trip_latched = false;                // the pump's trip latch at the last Advance
    std::vector<InputChecks> checks;          // per input message (inputs_)
    /// Per SecondSenderKind: when evidence of that kind was last seen (us; -1: never).
    std::int64_t second_sender_seen_us[kSecondSenderKinds] = {-1, -1, -1};
    // LCM publishing without allocation in steady state: channel names made once, messages
    // filled in place (their strings and vectors keep their capacity).
    std::string channel_telemetry, channel_temperatures, channel_alarm;
    pumptherm::temperatures_t temperatures_msg;
    pumptherm::telemetry_t telemetry_msg;
    pumptherm::alarm_t alarm_msg;
  };
  struct Route {
    std::uint32_t pump;
    std::uint32_t message;  // into inputs_
  };
  /// The route of frame `f` on interface `iface`; pump kNoPump when no pump uses it.
  Route FindRoute(std::size_t iface, const protocol::CanFrame& f) const;
  /// Evidence of a second sender in frame `tf` on interface `iface` for pump `pump` (kNoPump:
  /// the gateway's heartbeat ID, every pump of that interface): counted, the pumps' second-sender
  /// warning raised, and named in the journal once (again after a quiet second_sender_clear_s).
  /// `what`: the evidence in words.
  void SecondSender(std::size_t iface, std::uint32_t pump, SecondSenderKind kind,
                    const protocol::TimedFrame& tf, const std::string& what);
  /// The second-sender checks of input frame `tf` of the route `r`; `inputs`: its decoded inputs.
  void CheckSecondSender(std::size_t iface, const Route& r, const protocol::TimedFrame& tf,
                         const double* inputs);
  /// own_ids_ for pump `p`'s output messages, and the heartbeat on every configured interface.
  void AddOwnIds(const PumpIo& io, std::size_t p);

  /// Advance's work for pump `p`: its thermal steps or silence check, then its due outputs.
  void AdvancePump(std::size_t p, std::int64_t now_us, OutputSink& sink);
  /// Gateway health: per-pump frame rates and the health message, when due.
  void AdvanceHealth(std::int64_t now_us, OutputSink& sink);
  /// The earliest time AdvancePump(p) has work: the pump's next thermal step or silence check,
  /// and, unless only its silence is timed, its output plans and LCM period; kDueNow while an
  /// alarm or mismatch change is unsent.
  std::int64_t PumpDueUs(std::size_t p) const;
  /// Pump `p` (or every pump) has work at the next Advance.
  void MarkDue(std::size_t p) {
    io_[p].due_us = kDueNow;
    next_due_us_ = kDueNow;
  }
  void MarkAllDue();
  void RateLimitedClear(PumpIo& io, const std::string& pump, const std::string& iface);
  /// A refused clear (counted by the caller) from `source`: a warning with structured fields
  /// (PUMP=, SOURCE=, RESULT=refused, REASON=) unless the audit's rate limit holds it back; the
  /// lines held back are summarised per source.
  void LogRefusedClear(const std::string& pump, const std::string& source,
                       const std::string& reason, const std::string& text);
  /// The summary lines for refused clears not logged, once their window has ended.
  void ReportRefusedClearsHeldBack(std::int64_t now_us);
  /// The pump named `name`, or pumps_.size().
  std::size_t PumpIndex(const std::string& name) const;
  /// Makes the clear of pump `p` durable before it acts: the safety state with its latch of
  /// `node` (every latch: empty) removed and, for an LCM command `m`, its counter taken.
  bool CommitClear(std::size_t p, const std::string& node, const pumptherm::alarm_clear_t* m,
                   std::string* error);
  /// The rest of ClearFromLcm once the signature held: the node, durability, the clear, the
  /// answer. Returns true when accepted.
  bool ActOnSignedClear(std::size_t p, const pumptherm::alarm_clear_t& m,
                        const ClearCheckResult& check, std::int64_t now_us, OutputSink& sink);
  void Emit(std::size_t pump, OutputPlan& plan, std::int64_t time_us, OutputSink& sink);
  void PublishClearReply(const pumptherm::alarm_clear_reply_t& reply, std::int64_t now_us,
                         OutputSink& sink);
  /// One frame of `plan`; `node` is the model node of a node-indexed message, else -1.
  void EmitFrame(std::size_t pump, OutputPlan& plan, int node, std::int64_t time_us,
                 OutputSink& sink);
  // Construction, step by step (gateway_setup.cpp); each throws ConfigError naming the key.
  using ModelCache = std::map<std::string, std::shared_ptr<const estimators::ThermalModel>>;
  /// The DBC and the mapping, with the DBC's warnings logged.
  void LoadFrameLayout();
  /// inputs_: the input messages and the inputs each carries.
  void IndexInputMessages();
  /// Pump `p` of the configuration: its motor, model (shared through `models`), outputs, routes.
  void AddPump(std::size_t p, ModelCache& models);
  estimators::MotorDescription LoadPumpMotor(const PumpConfig& pc, const std::string& key) const;
  std::shared_ptr<const estimators::ThermalModel> LoadPumpModel(const PumpConfig& pc,
                                                                const std::string& key,
                                                                ModelCache& models) const;
  /// One output plan per output message of the mapping, for a pump with `model`.
  void BuildOutputPlans(PumpIo& io, const estimators::ThermalModel& model) const;
  /// routes_ and standard_routes_ for pump `p`'s input frames.
  void AddRoutes(const PumpIo& io, std::size_t p, const std::string& key);
  /// Throws ConfigError at the key's line, listing the model's nodes, if measured_node,
  /// magnet_node, rotor_node or a node with alarm levels is not a node of `model`.
  void CheckPumpNodes(const PumpConfig& pc, const std::string& key,
                      const estimators::ThermalModel& model) const;
  /// Throws ConfigError (at dbc.file) if a mapped output that can be unknown has no "not
  /// available" raw value in the DBC, or an output message has no cycle time and no
  /// output_periods_s override: what would otherwise go out wrong without a word.
  void CheckOutputSignals(const std::string& dbc_path, const std::string& mapping_path) const;
  /// Throws ConfigError naming the pump and node if a node of `model` has no CAN output, or
  /// cannot be named by alarm_node.
  void CheckNodeOutputs(const PumpConfig& pc, const std::string& key,
                        const estimators::ThermalModel& model) const;
  void FillTemperatures(const Pump& p, pumptherm::temperatures_t& m) const;
  void FillTelemetry(std::size_t pump_index, pumptherm::telemetry_t& m) const;
  void FillAlarm(const Pump& p, pumptherm::alarm_t& m) const;
  /// Journal line for a new mismatch verdict (state, effect, onset).
  void LogMismatch(const Pump& pump) const;
  void FillHealth(std::int64_t now_us, pumptherm::gateway_health_t& m) const;
  /// What the published fields of pump `p` are read from; `node` the model node of a
  /// node-indexed frame, else -1.
  FieldSource Source(std::size_t p, int node) const;

  DaemonConfig config_;
  protocol::Dbc dbc_;
  std::unique_ptr<protocol::DbcCodec> codec_;
  protocol::SignalMapping mapping_;
  FrameCounter counter_;
  GatewayCounters counters_;
  MqttHealth mqtt_health_;
  std::int64_t wall_offset_us_ = 0;
  std::vector<InputMessage> inputs_;
  std::vector<std::unique_ptr<Pump>> pumps_;
  std::vector<PumpIo> io_;
  std::unordered_map<std::uint64_t, Route> routes_;
  /// The routes of 11-bit IDs again, kStandardIds per interface (pump kNoPump: none): an index
  /// instead of a hash lookup for the common case.
  static constexpr std::size_t kStandardIds = 2048;
  static constexpr std::uint32_t kNoPump = std::numeric_limits<std::uint32_t>::max();
  std::vector<Route> standard_routes_;
  /// The gateway's own output IDs (RouteKey) -> the pump they belong to (kNoPump: the
  /// heartbeat): a frame of one received is another sender's.
  std::unordered_map<std::uint64_t, std::uint32_t> own_ids_;
  std::vector<double> values_;  // decode/encode buffer (largest message)
  std::string channel_health_;
  pumptherm::gateway_health_t health_msg_;
  std::vector<std::uint8_t> lcm_bytes_;  // LCM encoding buffer (largest message)
  mutable std::vector<estimators::AlarmCondition> conditions_;  // FillAlarm's buffer
  ClearAuthenticator clear_auth_;
  SafetyCommit safety_commit_;
  /// Refused clears can come as fast as anyone sends them: at most kRefusedClearLogBurst lines
  /// per kRefusedClearLogWindow_s, the rest summarised per source (every one is counted in
  /// clears_refused).
  static constexpr int kRefusedClearLogBurst = 5;
  static constexpr double kRefusedClearLogWindow_s = 60.0;
  ClearAudit clear_audit_{kRefusedClearLogBurst, kRefusedClearLogWindow_s};
  std::int64_t start_us_ = -1;
  std::int64_t next_health_us_ = -1;
  std::int64_t last_now_us_ = -1;
  std::int64_t next_due_us_ = kDueNow;  ///< min of next_health_us_ and every io_[p].due_us
};

}  // namespace pumptherm::daemon
