#pragma once
/// Writing a `Dbc` back as DBC text, so that `ParseDbc(FormatDbc(dbc))` gives the same messages,
/// signals, value descriptions, comments and attributes (`pumptherm dbc export` writes a site's
/// DBC with it).
///
/// What is written: `VERSION`, `NS_`, `BS_`, `BU_`, `VAL_TABLE_`, `BO_` with its `SG_` lines
/// (multiplexer indicators `M`, `mN`, `mNM`), `CM_`, `BA_DEF_`, `BA_DEF_DEF_`, `BA_`, `VAL_`,
/// `SIG_VALTYPE_` and `SG_MUL_VAL_` (for every multiplexed signal whose ranges are not one value
/// of the message's top multiplexer). Numbers are plain decimals (`0.00001`, never `1E-005`:
/// some tools drop signals written with an exponent) with the digits that read back to the same
/// double. A name longer than 32 characters, or one that is not a DBC identifier, is written as
/// Vector's tools write it: a short name (its first 27 usable characters, `_` and a 4-digit
/// number) in the statements and the whole name in `SystemSignalLongSymbol`,
/// `SystemMessageLongSymbol` or `SystemNodeLongSymbol`, which ParseDbc, cantools and canmatrix
/// read back as the name. What the reader drops (environment variables, signal groups, `BO_TX_BU_`)
/// is not written.
/// Pure formatting: no I/O.

#include <string>

#include "protocol/dbc.hpp"

namespace pumptherm::protocol {

/// The DBC text of `dbc`. Never throws for a Dbc that ParseDbc produced; a name that is empty
/// throws std::invalid_argument.
std::string FormatDbc(const Dbc& dbc);

/// `v` as a plain decimal that reads back as the same double ("0.00001", "-50", "0.1"); "nan"
/// and "inf" are not DBC numbers and throw std::invalid_argument.
std::string DbcNumber(double v);

}  // namespace pumptherm::protocol
