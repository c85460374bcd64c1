#include "server/cli/args.h"

#include <iostream>
#include <sstream>

#include "engine/util/check.h"

namespace omnirig::cli {

ArgParser::ArgParser(std::string command, std::string summary)
    : command_(std::move(command)), summary_(std::move(summary)) {}

void ArgParser::AddOption(const std::string& name, const std::string& default_value,
                          const std::string& help) {
  order_.push_back(name);
  options_[name] = Option{default_value, help, false};
}

void ArgParser::AddFlag(const std::string& name, const std::string& help) {
  order_.push_back(name);
  options_[name] = Option{"", help, true};
}

void ArgParser::SetPositional(const std::string& name, const std::string& help) {
  positional_name_ = name;
  positional_help_ = help;
}

std::string ArgParser::Help() const {
  std::ostringstream os;
  os << "usage: omnirig " << command_ << " [options]"
     << (positional_name_.empty() ? "" : " " + positional_name_) << "\n\n"
     << summary_ << "\n\noptions:\n";
  for (const auto& name : order_) {
    const Option& option = options_.at(name);
    os << "  " << (name.size() == 1 ? "-" : "--") << name << (option.is_flag ? "" : " VALUE") << "\n      " << option.help;
    if (!option.is_flag && !option.default_value.empty()) {
      os << " (default: " << option.default_value << ")";
    }
    os << "\n";
  }
  os << "  --help\n      show this help\n";
  if (!positional_name_.empty()) os << "\n" << positional_name_ << ": " << positional_help_ << "\n";
  return os.str();
}

bool ArgParser::Parse(const std::vector<std::string>& args) {
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& arg = args[i];
    if (arg == "--help" || arg == "-h") {
      std::cout << Help();
      exit_code_ = 0;
      return false;
    }
    // Options are `--name VALUE`, `--name=VALUE`, or `-x VALUE` for one-letter names.
    const bool short_option = arg.size() == 2 && arg[0] == '-' && arg[1] != '-';
    if ((arg.rfind("--", 0) == 0 && arg.size() > 2) || short_option) {
      std::string name = arg.substr(short_option ? 1 : 2), value;
      const auto eq = name.find('=');
      bool has_inline_value = false;
      if (eq != std::string::npos) {
        value = name.substr(eq + 1);
        name = name.substr(0, eq);
        has_inline_value = true;
      }
      const auto it = options_.find(name);
      if (it == options_.end()) {
        std::cerr << "omnirig " << command_ << ": unknown option " << arg
                  << " (see --help)\n";
        exit_code_ = 2;
        return false;
      }
      if (it->second.is_flag) {
        values_[name] = "1";
        continue;
      }
      if (!has_inline_value) {
        if (i + 1 >= args.size()) {
          std::cerr << "omnirig " << command_ << ": option --" << name << " needs a value\n";
          exit_code_ = 2;
          return false;
        }
        value = args[++i];
      }
      values_[name] = value;
    } else {
      positional_.push_back(arg);
    }
  }
  return true;
}

std::string ArgParser::Get(const std::string& name) const {
  const auto it = values_.find(name);
  if (it != values_.end()) return it->second;
  const auto opt = options_.find(name);
  OMNIRIG_CHECK(opt != options_.end(), "undeclared option --" << name);
  return opt->second.default_value;
}

double ArgParser::GetDouble(const std::string& name) const {
  const std::string text = Get(name);
  try {
    size_t used = 0;
    const double value = std::stod(text, &used);
    if (used == text.size()) return value;
  } catch (const std::exception&) {
  }
  throw InvalidArgument("--" + name + " expects a number, got '" + text + "'");
}

int ArgParser::GetInt(const std::string& name) const {
  const std::string text = Get(name);
  try {
    size_t used = 0;
    const int value = std::stoi(text, &used);
    if (used == text.size()) return value;
  } catch (const std::exception&) {
  }
  throw InvalidArgument("--" + name + " expects an integer, got '" + text + "'");
}

bool ArgParser::Has(const std::string& name) const { return values_.count(name) > 0; }

}  // namespace omnirig::cli
