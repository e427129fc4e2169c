#include "daemon/state_store.hpp"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <system_error>
#include <thread>

namespace pumptherm::daemon {
namespace {

std::string TempDir() {
  const auto dir = std::filesystem::path(::testing::TempDir()) /
                   ("state_store_test_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir.string();
}

TEST(StateStore, WritesReplacesAndReads) {
  const std::string dir = TempDir();
  const std::string path = dir + "/state.toml";
  EXPECT_FALSE(ReadFileIfExists(path).has_value());
  WriteFileAtomically(path, "first");
  EXPECT_EQ(ReadFileIfExists(path).value(), "first");
  WriteFileAtomically(path, std::string(200000, 'x'));
  EXPECT_EQ(ReadFileIfExists(path).value().size(), 200000U);
  EXPECT_FALSE(std::filesystem::exists(path + ".tmp"));
  struct stat st {};
  ASSERT_EQ(::stat(path.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600U);
}

TEST(StateStore, FailureLeavesTheOldFileAndNamesThePath) {
  const std::string dir = TempDir();
  const std::string path = dir + "/state.toml";
  WriteFileAtomically(path, "old");
  // The temporary cannot be created where a directory of that name stands.
  std::filesystem::create_directory(path + ".tmp");
  try {
    WriteFileAtomically(path, "new");
    FAIL() << "no error";
  } catch (const std::system_error& e) {
    EXPECT_NE(std::string(e.what()).find("cannot create " + path + ".tmp"), std::string::npos)
        << e.what();
  }
  EXPECT_EQ(ReadFileIfExists(path).value(), "old");
}

// kill -9 in the middle of a write (the test pause holds the writer after half the contents,
// as gateway.test_state_write_pause_s does in system.fault_injection): the target keeps the old
// contents whole; the cut-short temporary is only ever the temporary; the next write succeeds.
TEST(StateStore, KillDuringAWriteLeavesTheOldFileWhole) {
  const std::string dir = TempDir();
  const std::string path = dir + "/state.toml";
  const std::string old_text(10000, 'o');
  const std::string new_text(30000, 'n');
  WriteFileAtomically(path, old_text);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    WriteFileAtomically(path, new_text, 0600, 5.0);
    ::_exit(0);
  }
  const std::string tmp = TemporaryPathOf(path);
  EXPECT_EQ(tmp, path + ".tmp");
  std::error_code ec;
  for (int k = 0; k < 500 && std::filesystem::file_size(tmp, ec) != new_text.size() / 2; ++k) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_EQ(std::filesystem::file_size(tmp, ec), new_text.size() / 2)
      << "the writer never reached its pause";
  ASSERT_EQ(::kill(child, SIGKILL), 0);
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);
  EXPECT_EQ(ReadFileIfExists(path).value(), old_text);
  EXPECT_EQ(ReadFileIfExists(tmp).value(), new_text.substr(0, new_text.size() / 2));
  WriteFileAtomically(path, new_text);
  EXPECT_EQ(ReadFileIfExists(path).value(), new_text);
  EXPECT_FALSE(std::filesystem::exists(tmp));
}

TEST(StateStore, UnreadableIsAnErrorButMissingIsNot) {
  const std::string dir = TempDir();
  EXPECT_FALSE(ReadFileIfExists(dir + "/none").has_value());
  EXPECT_THROW(ReadFileIfExists(dir), std::system_error);  // a directory: read fails (EISDIR)
}

}  // namespace
}  // namespace pumptherm::daemon
