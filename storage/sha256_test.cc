#include "storage/sha256.h"

#include <gtest/gtest.h>

namespace omnirig::storage {
namespace {

TEST(Sha256, KnownVectors) {
  EXPECT_EQ(Sha256Hex(""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  EXPECT_EQ(Sha256Hex("abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
}

TEST(Sha256, StreamingEqualsOneShot) {
  std::string data;
  for (int i = 0; i < 100000; ++i) data.push_back(static_cast<char>(i * 31 + 7));
  Sha256 hasher;
  for (size_t offset = 0; offset < data.size(); offset += 4093) {
    hasher.Update(std::string_view(data).substr(offset, 4093));
  }
  EXPECT_EQ(hasher.HexDigest(), Sha256Hex(data));
}

}  // namespace
}  // namespace omnirig::storage
