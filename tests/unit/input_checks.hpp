// Helpers shared by the unit tests of the input readers (test_readers,
// test_mesh_formats, test_parser_hardening): a fresh temporary folder per test to
// write input files into, and checks on the one-line InputError a reader throws.
#pragma once

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>
#include <string>

#include "common/errors.hpp"

namespace softbody::testing {

namespace fs = std::filesystem;

// A test fixture with its own folder, removed after the test:
// <tmp>/softbody_test_<suite>_<test>_<random>.
class TempFolderTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::random_device entropy;
    const auto *info = ::testing::UnitTest::GetInstance()->current_test_info();
    folder_ = fs::temp_directory_path() / ("softbody_test_" + std::string(info->test_suite_name()) +
                                           "_" + info->name() + "_" + std::to_string(entropy()));
    fs::create_directories(folder_);
  }
  void TearDown() override { fs::remove_all(folder_); }

  // Writes `text` to folder/name (creating its sub-folders) and returns the full path.
  std::string Write(const std::string &name, const std::string &text) const {
    const fs::path path = folder_ / name;
    fs::create_directories(path.parent_path());
    std::ofstream(path, std::ios::binary) << text;
    return path.string();
  }

  fs::path folder_;
};

// The message of the InputError that `read` throws; a test failure when it throws
// nothing or another exception.
template <class Read>
std::string InputErrorOf(Read read) {
  try {
    read();
  } catch (const InputError &error) {
    return error.what();
  } catch (const std::exception &error) {
    ADD_FAILURE() << "not an InputError: " << error.what();
    return "";
  }
  ADD_FAILURE() << "no InputError thrown";
  return "";
}

inline ::testing::AssertionResult Contains(const std::string &text, const std::string &part) {
  if (text.find(part) != std::string::npos) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << "'" << text << "' lacks '" << part << "'";
}

#define EXPECT_CONTAINS(text, part) EXPECT_TRUE(::softbody::testing::Contains((text), (part)))

// "path:line:" as errors.hpp's Where() spells it.
inline std::string At(const std::string &path, int line) {
  return path + ":" + std::to_string(line) + ":";
}

}  // namespace softbody::testing
