#pragma once
/// Every value the gateway publishes about a pump, declared once (in the manner of moteus,
/// which declares a struct's fields once for config, telemetry and persistence): its name (the
/// signal mapping's output key), unit, where it goes on CAN by default (the shipped
/// protocol/pumptherm.dbc), its LCM field, its CSV column and how the CSV writes it, and how
/// its value is read from the pump's estimate. The CAN encoder, the LCM messages and the
/// offline CSV are filled from this list (docs/architecture.md, "Published values").
///
/// Not here: the node temperatures and sds (one per model node: LCM arrays, CSV columns
/// `<node>_degC`, CAN through outputs.nodes or the node-indexed message, whose per-node fields are
/// here), the alarm's conditions and the channels' strings (LCM), and the saved state, which
/// is the estimator's own state (PumpEstimatorState), not a published value.

#include <cstdint>
#include <limits>
#include <span>
#include <string>
#include <string_view>
#include <variant>

#include "estimators/pump_estimator.hpp"
#include "protocol/mapping.hpp"
#include "pumptherm/alarm_t.hpp"
#include "pumptherm/temperatures_t.hpp"

namespace pumptherm::daemon {

/// What a field's value is read from: the pump's estimate and what only the gateway knows.
struct FieldSource {
  const estimators::PumpEstimate* estimate = nullptr;
  const estimators::ThermalModel* model = nullptr;
  int node = -1;  ///< the model node of a node-indexed frame (-1: none)
  double uptime_s = std::numeric_limits<double>::quiet_NaN();
  double frame_rate_Hz = std::numeric_limits<double>::quiet_NaN();
  double lost_frames = std::numeric_limits<double>::quiet_NaN();
  double bus_state = std::numeric_limits<double>::quiet_NaN();  ///< DBC BusState code
  double nis_limit = std::numeric_limits<double>::infinity();   ///< alarms.nis_limit
  double wall_offset_us = 0.0;  ///< wall clock minus the pipeline's clock (Gateway)
};

/// An LCM field the value goes to (a member of temperatures_t or alarm_t), or none.
using LcmField =
    std::variant<std::monostate, double pumptherm::temperatures_t::*,
                 std::int8_t pumptherm::temperatures_t::*, double pumptherm::alarm_t::*,
                 std::int8_t pumptherm::alarm_t::*, std::int64_t pumptherm::alarm_t::*>;

/// How the CSV writes a value: fixed with `digits` decimals, general with `digits` significant
/// digits, an integer, or a word (PublishedField::word; a code is written as its word, the
/// numbers CAN and LCM carry beside them in docs/daemon.md, "Names"). A value that is not
/// available (NaN) is an empty cell, except `nan` in a fixed or general column.
struct CsvFormat {
  /// kFixedOrEmpty: fixed, and empty when there is none (NaN or infinite: time to trip).
  enum class Kind : std::uint8_t { kNone, kFixed, kGeneral, kInteger, kWord, kFixedOrEmpty };
  Kind kind = Kind::kNone;
  int digits = 0;
};

struct PublishedField {
  using Value = double (*)(const FieldSource&);
  /// Appends the CSV's word for the value to `out` (nothing for "not available").
  using Word = void (*)(const FieldSource&, std::string& out);
  PublishedField(std::string_view name_, std::string_view unit_, std::string_view dbc_message_,
                 std::string_view dbc_signal_, LcmField lcm_, std::string_view csv_column_,
                 CsvFormat csv_, Value value_, Word word_ = nullptr, std::string_view old_key_ = {},
                 bool always_known_ = false)
      : name(name_),
        unit(unit_),
        dbc_message(dbc_message_),
        dbc_signal(dbc_signal_),
        lcm(lcm_),
        csv_column(csv_column_),
        csv(csv_),
        value(value_),
        word(word_),
        old_key(old_key_),
        always_known(always_known_) {}

  std::string_view name;  ///< the mapping's output key
  std::string_view unit;  ///< "degC", "K", "ohm", "Wb", "s", "Hz", "" for a code or a count
  /// The shipped DBC's message and signal it goes to where the mapping names none (taken when
  /// the DBC has both); empty: only where a mapping names one.
  std::string_view dbc_message, dbc_signal;
  LcmField lcm;
  std::string_view csv_column;  ///< empty: not in the CSV
  CsvFormat csv;
  /// The value (NaN: not available, sent as the signal's "not available").
  Value value = nullptr;
  /// The CSV's word for a code (CsvFormat::Kind::kWord).
  Word word = nullptr;
  /// A key this output had before (still read, reported as deprecated).
  std::string_view old_key;
  /// Its value is never "not available" (a status, a count, a node index): its signal needs no
  /// reserved raw value (the configuration check asks one of every other output).
  bool always_known = false;
};

/// Every published field, in the CSV's column order.
std::span<const PublishedField> PublishedFields();
/// The field called `name`, or nullptr.
const PublishedField* FindPublishedField(std::string_view name);
/// The mapping's outputs: every field's key, default binding and old key.
std::span<const protocol::OutputSpec> MappingOutputs();

/// The output whose change sends its message at once (the alarm).
inline constexpr std::string_view kAlarmLevelKey = "alarm_level";

/// alarm_node's value for the winding temperature from resistance; the next value is "none".
inline constexpr std::size_t kAlarmNodeWindingRes = 14;

/// Sets every LCM field of `m` that a published field names.
void FillLcm(const FieldSource& source, pumptherm::temperatures_t& m);
void FillLcm(const FieldSource& source, pumptherm::alarm_t& m);

/// The CSV header of the published fields (",col,col..."), and one row's cells (",v,v...")
/// appended to `out`.
std::string CsvHeader();
void AppendCsvRow(const FieldSource& source, std::string& out);

}  // namespace pumptherm::daemon
