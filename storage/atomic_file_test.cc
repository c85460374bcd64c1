#include "storage/atomic_file.h"

#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "testing/storage/test_util.h"

namespace omnirig::storage {
namespace {

std::string ReadAll(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream content;
  content << in.rdbuf();
  return content.str();
}

int CountFiles(const std::filesystem::path& dir) {
  int count = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir))
    count += entry.is_regular_file();
  return count;
}

TEST(AtomicFile, CommitWritesContentAndDigest) {
  testing::TempDir dir;
  const auto path = dir.path() / "sub" / "a.bin";
  const FileDigest digest = WriteFileAtomically(path, "hello");
  EXPECT_EQ(ReadAll(path), "hello");
  EXPECT_EQ(digest.size, 5);
  EXPECT_EQ(digest.sha256, Sha256Hex("hello"));
  const FileDigest reread = DigestFile(path);
  EXPECT_EQ(reread.size, digest.size);
  EXPECT_EQ(reread.sha256, digest.sha256);
  EXPECT_EQ(CountFiles(dir.path() / "sub"), 1);  // no temporary left behind
}

TEST(AtomicFile, AbandonedWriteLeavesOldContent) {
  testing::TempDir dir;
  const auto path = dir.path() / "a.bin";
  WriteFileAtomically(path, "old");
  {
    AtomicFileWriter writer(path);
    writer.Append("new content that is never committed");
    EXPECT_EQ(CountFiles(dir.path()), 2);  // the temporary exists while writing
  }
  EXPECT_EQ(ReadAll(path), "old");
  EXPECT_EQ(CountFiles(dir.path()), 1);
}

TEST(AtomicFile, ReplacesExistingFile) {
  testing::TempDir dir;
  const auto path = dir.path() / "a.bin";
  WriteFileAtomically(path, "first");
  WriteFileAtomically(path, "second");
  EXPECT_EQ(ReadAll(path), "second");
}

TEST(AtomicFile, TemporaryNamesAreRecognised) {
  EXPECT_TRUE(IsTemporaryFileName(".a.png.part-0123456789ab"));
  EXPECT_FALSE(IsTemporaryFileName("a.png"));
  EXPECT_FALSE(IsTemporaryFileName("a.part-1"));
}

}  // namespace
}  // namespace omnirig::storage
