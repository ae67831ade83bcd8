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
  } catch (const json::parse_error& e) {
    // nlohmann's message ends with the bytes it read ("; last read: '...'"):
    // not echoed (input_text.h); the position and the kind of error are.
    std::string what = e.what();
    const auto last = what.find("; last read:");
    if (last != std::string::npos) what.resize(last);
    throw InputError(file, "byte " + std::to_string(e.byte), "not valid JSON: " + what);
  } catch (const json::exception& e) {  // e.g. a number out of range: its message quotes the number
    std::string what = e.what();
    const auto quote = what.find('\'');
    if (quote != std::string::npos) what.resize(quote);
    throw InputError(file, std::string("not valid JSON: ") + what);
  }
}

}  // namespace lfrecon
