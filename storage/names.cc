#include "storage/names.h"

#include <stdexcept>
#include <vector>

namespace omnirig::storage {
namespace {

bool IsAllowedChar(char c) {
  return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '.' ||
         c == '_' || c == '-' || c == '+';
}

void CheckComponent(const std::string& name, const std::string& component) {
  if (component.empty()) {
    throw std::invalid_argument("name '" + name + "' has an empty path component");
  }
  if (component[0] == '.') {
    throw std::invalid_argument("name '" + name +
                                "' has a hidden or relative component (leading '.')");
  }
  if (component.size() > kMaxNameComponentLength) {
    throw std::invalid_argument("name '" + name + "' has a component longer than " +
                                std::to_string(kMaxNameComponentLength) + " characters");
  }
  for (char c : component) {
    if (!IsAllowedChar(c)) {
      throw std::invalid_argument("name '" + name + "' holds a character outside [A-Za-z0-9._+-]");
    }
  }
}

}  // namespace

std::string CheckSafeName(const std::string& name, int max_levels) {
  if (name.empty()) throw std::invalid_argument("name is empty");
  if (name.size() > kMaxNameLength) {
    throw std::invalid_argument("name is longer than " + std::to_string(kMaxNameLength) +
                                " characters");
  }
  if (name[0] == '/') throw std::invalid_argument("name '" + name + "' is an absolute path");
  std::vector<std::string> components;
  size_t start = 0;
  while (true) {
    const size_t slash = name.find('/', start);
    components.push_back(name.substr(start, slash - start));
    if (slash == std::string::npos) break;
    start = slash + 1;
  }
  if (static_cast<int>(components.size()) > max_levels) {
    throw std::invalid_argument("name '" + name + "' has more than " +
                                std::to_string(max_levels - 1) + " folder level(s)");
  }
  for (const std::string& component : components) CheckComponent(name, component);
  return name;
}

}  // namespace omnirig::storage
