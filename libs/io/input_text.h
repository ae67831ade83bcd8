#pragma once
// Error messages about untrusted input files reach clients (the ingest
// daemon's ErrorReply, a job's status message): they name the file and the
// position (field, line, byte) and never echo what the file holds beyond a
// short, sanitized token, so a bad file cannot make a daemon repeat its
// contents (or a secret pasted into it) to whoever submitted it.
#include <string>

namespace lfrecon {

constexpr std::size_t kMaxInputTokenChars = 32;

// `text` quoted for an error message: in single quotes, printable ASCII only
// (every other byte becomes '?'); a text longer than kMaxInputTokenChars is
// not quoted at all, only its length is given ("a text of N bytes").
std::string InputToken(const std::string& text);

}  // namespace lfrecon
