#include "io/json_file.h"

#include <fstream>
#include <string>

#include "util/error.h"

namespace lfrecon {

namespace {
struct TooDeep {};
}  // namespace

nlohmann::json ReadJsonFile(const std::filesystem::path& path, int max_depth) {
  using nlohmann::json;
  const std::string file = path.string();
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(file, "cannot open file");
  // The callback sees every object and array as it starts, with its depth
  // (0: the root value); throwing stops the parse before anything deeper is built.
  const json::parser_callback_t limit = [max_depth](int depth, json::parse_event_t event, json&) {
    if ((event == json::parse_event_t::object_start || event == json::parse_event_t::array_start) &&
        depth >= max_depth)
      throw TooDeep{};
    return true;
  };
  try {
    return json::parse(in, limit);
  } catch (const TooDeep&) {
    throw InputError(file, "JSON nested deeper than " + std::to_string(max_depth) + " levels");
  } catch (const json::exception& e) {
    throw InputError(file, std::string("not valid JSON: ") + e.what());
  }
}

}  // namespace lfrecon
