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

// Text a peer chose that is worth showing in logs and messages (a worker's
// name, a worker's error, an aggregator's error reply, an exception's text
// that holds a client's path): printable ASCII only (every other byte becomes
// '?', so no newline or escape sequence can forge a log line or a terminal's
// state), at most `max_chars` of it, a longer text cut and its length given
// ("abc... (10240 bytes)"). Not quoted.
std::string PeerText(const std::string& text, std::size_t max_chars = 256);

}  // namespace lfrecon
