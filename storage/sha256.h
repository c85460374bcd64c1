#pragma once
// Streaming SHA-256 (OpenSSL's EVP digest, which uses the CPU's SHA extensions when present),
// used to fingerprint every stored image and artifact.

#include <cstddef>
#include <string>
#include <string_view>

typedef struct evp_md_ctx_st EVP_MD_CTX;

namespace omnirig::storage {

class Sha256 {
 public:
  Sha256();
  ~Sha256();
  Sha256(const Sha256&) = delete;
  Sha256& operator=(const Sha256&) = delete;

  void Update(const void* data, size_t size);
  void Update(std::string_view data) { Update(data.data(), data.size()); }
  // Lower-case hex digest (64 characters). Ends the computation: call once.
  std::string HexDigest();

 private:
  EVP_MD_CTX* context_;
};

// Hex SHA-256 of a whole buffer.
std::string Sha256Hex(std::string_view data);

}  // namespace omnirig::storage
