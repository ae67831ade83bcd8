#pragma once
// Errors that reach the user. An InputError names the file (and, where it
// applies, the field) that is wrong, so the CLI can print one clear line and
// exit with code 1 instead of crashing.
#include <stdexcept>
#include <string>

namespace lfrecon {

class InputError : public std::runtime_error {
 public:
  InputError(std::string file, std::string field, const std::string& message);
  InputError(std::string file, const std::string& message) : InputError(std::move(file), "", message) {}

  const std::string& file() const { return file_; }
  const std::string& field() const { return field_; }

 private:
  std::string file_;
  std::string field_;
};

// An option struct whose Check() failed: a usage error (exit code 2 in the CLI).
class OptionError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

}  // namespace lfrecon

// Validates an option field; throws OptionError naming the expression.
#define LFRECON_CHECK_OPTION(cond)                                                  \
  do {                                                                              \
    if (!(cond)) throw ::lfrecon::OptionError(std::string("invalid option: ") + #cond); \
  } while (0)
