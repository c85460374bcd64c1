// The streamed archive read back by Info-ZIP's unzip (its own CRC and size checks, names and
// contents), plain and with ZIP64 fields forced on small files; and a file that differs from its
// record stops the archive.

#include "server/zip_stream.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <map>
#include <random>
#include <sstream>

#include "storage/sha256.h"

namespace omnirig::server {
namespace {

namespace fs = std::filesystem;

class ZipStreamTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("omnirig_zip_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "in");
  }
  void TearDown() override { fs::remove_all(dir_); }

  ZipEntry Write(const std::string& name, size_t size, unsigned seed) {
    std::mt19937 random(seed);
    std::string bytes(size, '\0');
    for (char& c : bytes) c = static_cast<char>(random());
    const fs::path path = dir_ / "in" / ("f" + std::to_string(seed));
    std::ofstream(path, std::ios::binary) << bytes;
    contents_[name] = bytes;
    return {name, path, static_cast<int64_t>(size), storage::Sha256Hex(bytes)};
  }

  // Streams the archive to a file; returns its path.
  fs::path Archive(ZipStream& zip) {
    const fs::path path = dir_ / "out.zip";
    std::ofstream out(path, std::ios::binary);
    std::string piece;
    while (zip.Next(piece)) {
      out << piece;
      piece.clear();
    }
    return path;
  }

  static std::string Run(const std::string& command, int* status) {
    std::string output;
    FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
    char buffer[4096];
    size_t got;
    while ((got = std::fread(buffer, 1, sizeof(buffer), pipe)) > 0) output.append(buffer, got);
    *status = ::pclose(pipe);
    return output;
  }

  // unzip -t passes, and each entry's bytes are the file's.
  void ExpectReadable(const fs::path& archive) {
    int status = 0;
    const std::string test = Run("unzip -t " + archive.string(), &status);
    EXPECT_EQ(status, 0) << test;
    EXPECT_NE(test.find("No errors detected"), std::string::npos) << test;
    std::istringstream names(Run("unzip -Z1 " + archive.string(), &status));
    std::vector<std::string> listed;
    for (std::string line; std::getline(names, line);) listed.push_back(line);
    ASSERT_EQ(listed.size(), contents_.size());
    for (const auto& [name, bytes] : contents_) {
      const std::string extracted = Run("unzip -p " + archive.string() + " '" + name + "'", &status);
      EXPECT_EQ(status, 0) << name;
      EXPECT_EQ(extracted.size(), bytes.size()) << name;
      EXPECT_TRUE(extracted == bytes) << name;
    }
  }

  fs::path dir_;
  std::map<std::string, std::string> contents_;
};

TEST_F(ZipStreamTest, ArchiveIsReadBackWhole) {
  ZipStream zip({Write("result.json", 1000, 1), Write("cam0/000001_range.png", 700000, 2),
                 Write("empty.txt", 0, 3)});
  const fs::path archive = Archive(zip);
  EXPECT_EQ(zip.offset(), fs::file_size(archive));
  ExpectReadable(archive);
}

TEST_F(ZipStreamTest, Zip64FieldsAreReadBack) {
  ZipStream zip({Write("a.bin", 300000, 4), Write("b.bin", 5, 5)}, /*zip64_from=*/1);
  ExpectReadable(Archive(zip));
}

TEST_F(ZipStreamTest, EmptyArchive) {
  ZipStream zip({});
  const fs::path archive = Archive(zip);
  EXPECT_EQ(fs::file_size(archive), 22u);  // the end record alone
}

TEST_F(ZipStreamTest, AFileThatDiffersFromItsRecordStopsTheArchive) {
  ZipEntry changed = Write("a.bin", 1000, 6);
  changed.sha256[0] = changed.sha256[0] == '0' ? '1' : '0';
  ZipStream zip({changed});
  std::string piece;
  EXPECT_THROW(
      {
        while (zip.Next(piece)) {
        }
      },
      std::runtime_error);
  ZipEntry shorter = Write("b.bin", 1000, 7);
  shorter.size = 2000;
  ZipStream zip2({shorter});
  EXPECT_THROW(
      {
        while (zip2.Next(piece)) {
        }
      },
      std::runtime_error);
  ZipEntry longer = Write("c.bin", 1000, 8);
  longer.size = 500;
  ZipStream zip3({longer});
  EXPECT_THROW(
      {
        while (zip3.Next(piece)) {
        }
      },
      std::runtime_error);
  ZipEntry gone = Write("d.bin", 10, 9);
  fs::remove(gone.path);
  ZipStream zip4({gone});
  EXPECT_THROW(zip4.Next(piece), std::runtime_error);
}

}  // namespace
}  // namespace omnirig::server
