// A GoogleTest fixture with a fresh temporary directory per test (removed afterwards), for the tests
// that write files: file(name) is a path inside it.
#pragma once

#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <string>

namespace vdbclay_test {

class TempDirTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() { openvdb::initialize(); }
    void SetUp() override
    {
        char tmpl[] = "/tmp/vdbclay-test-XXXXXX";
        ASSERT_NE(mkdtemp(tmpl), nullptr);
        dir = tmpl;
    }
    void TearDown() override
    {
        std::error_code ec;
        std::filesystem::remove_all(dir, ec);
    }
    std::string file(const std::string& name) const { return dir + "/" + name; }
    std::string dir;
};

} // namespace vdbclay_test
