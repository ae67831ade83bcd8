#include "util/error.h"

namespace lfrecon {
namespace {
std::string Compose(const std::string& file, const std::string& field, const std::string& message) {
  std::string out = file;
  if (!field.empty()) out += " [" + field + "]";
  if (!out.empty()) out += ": ";
  return out + message;
}
}  // namespace

InputError::InputError(std::string file, std::string field, const std::string& message)
    : std::runtime_error(Compose(file, field, message)), file_(std::move(file)), field_(std::move(field)) {}

}  // namespace lfrecon
