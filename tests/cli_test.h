// The fixture of the end-to-end bad-input suites (test_bad_input.cpp, test_bad_input_cli.cpp): a
// temporary directory per test, and the travbench binary run under `timeout` with stdin from
// /dev/null, its exit status, stdout and stderr apart, checked against the one-line error contract.
#pragma once
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "test_util.h"

namespace tb::test {

struct CliResult {
  int code;         // exit status; 128 + signal when killed; 124 when `timeout` stopped it
  std::string out;  // stdout
  std::string err;  // stderr
};

class CliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = temp_dir(std::string(::testing::UnitTest::GetInstance()->current_test_info()->test_suite_name()) + "_" +
                    ::testing::UnitTest::GetInstance()->current_test_info()->name());
  }
  void TearDown() override {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  std::string write(const std::string& name, const std::string& bytes) const {
    std::ofstream(dir_ / name, std::ios::binary) << bytes;
    return path(name);
  }

  // Runs the travbench binary with stdin from /dev/null (nothing may wait for input) under a
  // 120-second `timeout`, so a hang fails the test instead of stalling it.
  CliResult travbench(const std::string& args) const {
    const std::string err_file = path("stderr.txt");
    const std::string cmd = "timeout 120 " + std::string(TRAVBENCH_BINARY) + " " + args + " </dev/null 2>" + err_file;
    FILE* p = popen(cmd.c_str(), "r");
    std::string out;
    char buf[4096];
    while (size_t n = fread(buf, 1, sizeof buf, p)) out.append(buf, n);
    const int status = pclose(p);
    std::ifstream ef(err_file);
    std::string err((std::istreambuf_iterator<char>(ef)), {});
    return {WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status), out, err};
  }

  // The contract for bad input: non-zero exit (no signal, no timeout), nothing on stdout, exactly
  // one line on stderr, starting "travbench: error: " and containing every needle.
  void expect_rejected(const std::string& args, const std::vector<std::string>& needles) const {
    SCOPED_TRACE("travbench " + args);
    const CliResult r = travbench(args);
    EXPECT_NE(r.code, 0);
    EXPECT_NE(r.code, 124) << "timed out (hang?)";
    EXPECT_LT(r.code, 128) << "killed by signal " << r.code - 128;
    EXPECT_EQ(r.out, "");
    EXPECT_EQ(r.err.rfind("travbench: error: ", 0), 0u) << r.err;
    ASSERT_FALSE(r.err.empty());
    EXPECT_EQ(r.err.back(), '\n') << r.err;
    EXPECT_EQ(r.err.find('\n'), r.err.size() - 1) << "more than one line:\n" << r.err;
    for (const auto& n : needles) EXPECT_NE(r.err.find(n), std::string::npos) << "missing '" << n << "' in: " << r.err;
  }

  std::filesystem::path dir_;
};

}  // namespace tb::test
