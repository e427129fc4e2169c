#pragma once
/// The Sparkplug B messages of the MQTT sink (docs/mqtt.md), made from one step's published
/// values. Pure: no sockets, clock, threads or logging; time enters as an argument. The values
/// are read from the declaration of the published fields (daemon/published_fields.hpp), each
/// field once, plus each model node's temperature and sd, named as the CSV names them.
///
/// Sparkplug terms (Eclipse Sparkplug 3.0.0): the gateway is an edge node, each pump a device.
/// Topics are `spBv1.0/<group_id>/<type>/<edge_node_id>[/<device_id>]`; every payload but NDEATH
/// carries `seq` (0 for NBIRTH, then +1 per message, 255 wraps to 0); NBIRTH and NDEATH carry
/// the session number `bdSeq`.

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "daemon/published_fields.hpp"

namespace pumptherm::daemon::mqtt {

/// The Sparkplug message types pumptherm sends or reads.
enum class MessageType : std::uint8_t { kNBirth, kNDeath, kDBirth, kDDeath, kDData, kNCmd };
std::string_view MessageTypeName(MessageType type);

/// Whether `id` may be a Sparkplug group, edge node or device id: non-empty, at most 255 bytes,
/// none of '/', '+', '#' (they would split or wildcard the topic), no control characters.
bool ValidId(std::string_view id);

/// `spBv1.0/<group_id>/<type>/<edge_node_id>` and `/<device_id>` when it is not empty.
std::string Topic(std::string_view group_id, MessageType type, std::string_view edge_node_id,
                  std::string_view device_id = {});

/// Sparkplug data types pumptherm uses (the values of DataType in protocol/sparkplug_b.proto).
enum class DataType : std::uint32_t { kInt64 = 4, kUInt32 = 7, kDouble = 10, kBoolean = 11 };

/// One metric of a pump: its name (units in the name, as on CAN, LCM and in the CSV), unit
/// (the `engUnit` property of its birth; empty for a code or a count) and type.
struct MetricSpec {
  std::string name;
  std::string unit;
  DataType type = DataType::kDouble;
};

/// The metrics of a pump whose model has the nodes `node_names`: every published field (in
/// their declared order) but the three that exist only for the node-indexed CAN frame
/// (node_index, node_temp_degC, node_sd_K), then `<node>_degC` and `<node>_sd_K` per node. A
/// code (a field the CSV writes as a word) is a UInt32 of the number CAN and LCM carry; every
/// other value a Double.
std::vector<MetricSpec> DeviceMetrics(std::span<const std::string> node_names);

/// Writes one step's value of every metric of DeviceMetrics(<the model's nodes>) to `out`, in
/// that order (NaN: not available). `out.size()` must be the number of metrics; the nodes are
/// read from `source.estimate`. Allocates nothing: the loop calls it.
void FillDeviceValues(const FieldSource& source, std::span<double> out);

/// Whether an NCMD payload asks for a rebirth: a metric "Node Control/Rebirth" that is true
/// (spec 6.4.19). False for anything that does not decode.
bool RebirthRequested(std::string_view payload);

/// The edge node's birth/death sequence number, bdSeq (Sparkplug 3.0.0, "Edge Node Birth":
/// tck-id-message-flow-edge-node-birth-publish-will-message-payload-bdSeq): the will (NDEATH)
/// of each MQTT CONNECT packet carries the value of the previous CONNECT packet's plus one,
/// 255 wrapping to 0; the NBIRTH of that connection carries the same value
/// (tck-id-payloads-nbirth-bdseq-repeat). It counts CONNECT packets, not sessions that came up:
/// a CONNECT the broker refused or that was lost before its NBIRTH still used its number, and an
/// attempt that never sent a CONNECT (the broker unreachable) uses none. Starts at 0.
class BdSeq {
 public:
  /// The value for the will of the next CONNECT packet.
  std::uint64_t ForNextConnect() const { return next_; }
  /// A CONNECT packet with ForNextConnect() in its will went out: that value is now the
  /// session's (Current()), and the next CONNECT takes the one after it.
  void ConnectSent() {
    current_ = next_;
    next_ = (next_ + 1) % 256;
  }
  /// The value of the last CONNECT sent: for the NBIRTH and the NDEATH of its session.
  std::uint64_t Current() const { return current_; }

 private:
  std::uint64_t next_ = 0;
  std::uint64_t current_ = 0;
};

/// A pump as the encoder sees it: its device id and its metrics.
struct Device {
  std::string id;
  std::vector<MetricSpec> metrics;
};

/// The alias of metric `metric` of device `device` (unique in the edge node, spec 6.4.8): the
/// device's index + 1 in the upper 32 bits, the metric's index in the lower.
std::uint64_t Alias(std::size_t device, std::size_t metric);

/// Builds the payloads of one edge node's session: NBIRTH, then a DBIRTH per device, then
/// DDATA. Keeps the sequence number and each device's last sent values (DDATA carries only
/// what changed since). Throws std::out_of_range for a device index or a value count that is
/// not the device's.
class Encoder {
 public:
  explicit Encoder(std::vector<Device> devices);

  const std::vector<Device>& devices() const { return devices_; }

  /// NBIRTH of session `bd_seq` at `time_ms` (ms since the Unix epoch): bdSeq and
  /// "Node Control/Rebirth" (false). Starts the sequence again at 0 and forgets what was sent,
  /// so the DBIRTHs that follow carry every value.
  std::string NodeBirth(std::uint64_t bd_seq, std::uint64_t time_ms);
  /// NDEATH of session `bd_seq` (the MQTT will: no timestamp, no seq, spec 6.4.6).
  static std::string NodeDeath(std::uint64_t bd_seq);
  /// DBIRTH of `device`: every metric with its name, alias, type, `engUnit` and value.
  std::string DeviceBirth(std::size_t device, std::span<const double> values,
                          std::uint64_t time_ms);
  /// DDATA of `device`: the metrics whose value differs from the last sent (by alias, no
  /// name); empty when nothing changed (nothing to send). `every_metric`: all of them, changed
  /// or not (never empty: an alarm transition, complete in itself, also when it is sent again
  /// after births that already carried its values).
  std::string DeviceData(std::size_t device, std::span<const double> values, std::uint64_t time_ms,
                         bool every_metric = false);

 private:
  std::uint64_t NextSeq();

  std::vector<Device> devices_;
  std::vector<std::vector<double>> sent_;  ///< per device, the last sent values
  std::uint64_t seq_ = 0;
};

}  // namespace pumptherm::daemon::mqtt
