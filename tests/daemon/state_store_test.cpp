#include "daemon/state_store.hpp"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <system_error>

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
    EXPECT_NE(std::string(e.what()).find("cannot create " + path + ".tmp"), std::string::npos) << e.what();
  }
  EXPECT_EQ(ReadFileIfExists(path).value(), "old");
}

TEST(StateStore, UnreadableIsAnErrorButMissingIsNot) {
  const std::string dir = TempDir();
  EXPECT_FALSE(ReadFileIfExists(dir + "/none").has_value());
  EXPECT_THROW(ReadFileIfExists(dir), std::system_error);  // a directory: read fails (EISDIR)
}

}  // namespace
}  // namespace pumptherm::daemon
