#pragma once
/// Files that must never be left half-written: the daemon's saved estimator state.
///
/// WriteFileAtomically() writes a temporary file in the same directory, fsyncs it, renames it
/// over the target and fsyncs the directory, so after a crash (even kill -9 or power loss in
/// the middle) the target holds either the old or the new contents, never a mix.

#include <optional>
#include <string>

namespace pumptherm::daemon {

/// Replaces `path` with `contents` atomically; the file gets mode `mode` (0600 by default:
/// state belongs to the service alone). The temporary is `path` + ".tmp". Throws
/// std::system_error naming the path and the step that failed (e.g. ENOSPC on write); the old
/// file is then untouched and the temporary removed.
///
/// Tests only: with `test_pause_s` > 0 the write stops for that long after the first half of
/// `contents` (a kill -9 then lands in the middle of a write; gateway.test_state_write_pause_s).
void WriteFileAtomically(const std::string& path, const std::string& contents, int mode = 0600,
                         double test_pause_s = 0.0);

/// The temporary WriteFileAtomically() writes before renaming it over `path`.
std::string TemporaryPathOf(const std::string& path);

/// The contents of `path`, or nullopt when it does not exist. Throws std::system_error for any
/// other failure to read it.
std::optional<std::string> ReadFileIfExists(const std::string& path);

}  // namespace pumptherm::daemon
