// volcast-client: replay a camera path against a running server and write every frame plus
// a report (per frame: level, latency, render and encode time, error estimate, bytes).
//
//   volcast-client path.json -o out/ [--url ws://127.0.0.1:8080/ws]
//
// path.json:
//   {"volume": "builtin:demo",                      required
//    "viewport": {"width": 512, "height": 512},     optional (512²)
//    "quality_policy": {"mode": "automatic", ...},  optional, the request's fields
//    "interval_ms": 33,                             optional: time between camera messages
//    "cameras": [{scene-file camera}, ...]}         or "orbit": {"steps": 36, "degrees": 360}
//                                                   (about the volume's starting camera)
//
// The moves are sent between interaction_start and interaction_end, as a drag; the command
// then waits for the final frame. Latency is from sending the request a frame answers to
// receiving the frame.

#include "client/cpp/ws_client.hpp"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <thread>

namespace {
using nlohmann::json;
using Clock = std::chrono::steady_clock;
namespace fs = std::filesystem;

double ms(Clock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

// The starting camera's eye turned about the target around "up".
json orbit(const json &camera, double degrees) {
    auto v = [](const json &a) { return std::array<double, 3>{a[0], a[1], a[2]}; };
    const auto eye = v(camera.at("eye")), target = v(camera.at("target")), up0 = v(camera.at("up"));
    const double n = std::sqrt(up0[0] * up0[0] + up0[1] * up0[1] + up0[2] * up0[2]);
    const std::array<double, 3> k{up0[0] / n, up0[1] / n, up0[2] / n};
    const std::array<double, 3> p{eye[0] - target[0], eye[1] - target[1], eye[2] - target[2]};
    const double a = degrees * M_PI / 180, c = std::cos(a), s = std::sin(a);
    const double kp = k[0] * p[0] + k[1] * p[1] + k[2] * p[2];
    const std::array<double, 3> kxp{k[1] * p[2] - k[2] * p[1], k[2] * p[0] - k[0] * p[2], k[0] * p[1] - k[1] * p[0]};
    json out = camera;
    // Rodrigues' rotation formula.
    for (int i = 0; i < 3; ++i) out["eye"][size_t(i)] = target[size_t(i)] + p[size_t(i)] * c + kxp[size_t(i)] * s + k[size_t(i)] * kp * (1 - c);
    return out;
}

double percentile(std::vector<double> v, double q) {
    if (v.empty()) return 0;
    std::sort(v.begin(), v.end());
    return v[std::min(v.size() - 1, size_t(q * double(v.size() - 1) + 0.5))];
}
} // namespace

int main(int argc, char **argv) {
    CLI::App app{"Replay a camera path against a volcast server; write its frames and a report."};
    std::string pathFile, outDir, url = "ws://127.0.0.1:8080/ws", token;
    double timeoutS = 60;
    app.add_option("path", pathFile, "Camera path JSON")->required()->check(CLI::ExistingFile);
    app.add_option("-o,--output", outDir, "Folder for frames and report.json")->required();
    app.add_option("--url", url, "The server's WebSocket URL");
    app.add_option("--token", token, "Access token, if the server needs one");
    app.add_option("--timeout", timeoutS, "Seconds to wait for the final frame");
    CLI11_PARSE(app, argc, argv);
    try {
        json path;
        std::ifstream(pathFile) >> path;
        // ws://host:port/path
        if (!url.starts_with("ws://")) throw std::invalid_argument("--url must start with ws://");
        const std::string rest = url.substr(5);
        const std::string hostPort = rest.substr(0, rest.find('/'));
        const std::string wsPath = rest.find('/') == std::string::npos ? "/" : rest.substr(rest.find('/'));
        const std::string host = hostPort.substr(0, hostPort.rfind(':'));
        const auto port = uint16_t(std::stoi(hostPort.substr(hostPort.rfind(':') + 1)));
        volcast::client::Client client(host, port, wsPath);
        const auto timeout = std::chrono::milliseconds(int64_t(timeoutS * 1000));
        auto check = [](const volcast::client::Message &m) {
            if (m.decoded)
                if (auto *e = std::get_if<volcast::protocol::ProtocolError>(&*m.decoded))
                    throw std::runtime_error("server error " + std::string(volcast::protocol::errorCodeName(e->code)) +
                                             ": " + e->message);
            return json::parse(m.text);
        };

        json hello = {{"type", "hello"}, {"id", "hello"}, {"protocol", 1}, {"client", "volcast-client 0.1.0"}};
        if (!token.empty()) hello["token"] = token;
        client.sendText(hello.dump());
        check(volcast::client::waitForReply(client, "hello", timeout));
        client.sendText(json{{"type", "viewport"}, {"id", "viewport"}, {"image", path.value("viewport", json{{"width", 512}, {"height", 512}})}}.dump());
        if (path.contains("quality_policy")) {
            json p = path["quality_policy"];
            p["type"] = "quality_policy";
            p["id"] = "policy";
            client.sendText(p.dump());
        }
        client.sendText(json{{"type", "open_volume"}, {"id", "open"}, {"name", path.at("volume")}}.dump());
        const json state = check(volcast::client::waitForReply(client, "open", timeout));

        std::vector<json> cameras;
        if (path.contains("cameras")) {
            for (const auto &c : path["cameras"]) cameras.push_back(c);
        } else {
            const json o = path.value("orbit", json{{"steps", 36}, {"degrees", 360}});
            const int steps = o.value("steps", 36);
            for (int i = 1; i <= steps; ++i)
                cameras.push_back(orbit(state["scene"]["camera"], o.value("degrees", 360.0) * i / steps));
        }
        const auto interval = std::chrono::microseconds(int64_t(path.value("interval_ms", 33.0) * 1000));

        // Drain the opening ladder first, so that the report covers the path only.
        fs::create_directories(outDir);
        std::map<json, Clock::time_point> sentAt;
        std::vector<volcast::client::Frame> frames;
        std::vector<Clock::time_point> receivedAt;
        auto take = [&](volcast::client::Message m) -> bool {
            if (!m.isFrame) {
                check(m);
                return false;
            }
            frames.push_back(std::move(m.frame));
            receivedAt.push_back(m.received);
            return frames.back().header.final;
        };
        for (auto deadline = Clock::now() + timeout; Clock::now() < deadline;) {
            auto m = client.next(std::chrono::milliseconds(100));
            if (m && take(std::move(*m))) break;
        }
        frames.clear();
        receivedAt.clear();

        client.sendText(R"({"type":"interaction_start","id":"start"})");
        auto next = Clock::now();
        Clock::time_point lastInput;
        for (size_t i = 0; i < cameras.size(); ++i) {
            const json id = int(i + 1);
            client.sendText(json{{"type", "camera"}, {"id", id}, {"camera", cameras[i]}}.dump());
            lastInput = sentAt[id] = Clock::now();
            next += interval;
            while (Clock::now() < next)
                if (auto m = client.next(std::chrono::duration_cast<std::chrono::milliseconds>(next - Clock::now())))
                    take(std::move(*m));
        }
        client.sendText(R"({"type":"interaction_end","id":"end"})");
        bool final = false;
        for (auto deadline = Clock::now() + timeout; !final && Clock::now() < deadline;)
            if (auto m = client.next(std::chrono::milliseconds(100))) final = take(std::move(*m));
        client.close();

        json report = json::array();
        std::vector<double> interactiveLatency;
        for (size_t i = 0; i < frames.size(); ++i) {
            const auto &h = frames[i].header;
            const std::string file = "frame_" + std::to_string(h.seq) + "_L" + std::to_string(h.level) +
                                     (h.codec == volcast::protocol::Codec::Png ? ".png" : ".jpg");
            std::ofstream(fs::path(outDir) / file, std::ios::binary)
                .write(reinterpret_cast<const char *>(frames[i].image.data()), std::streamsize(frames[i].image.size()));
            json row = {{"seq", h.seq},          {"request", h.request}, {"level", h.level},
                        {"final", h.final},      {"codec", std::string(volcast::protocol::codecName(h.codec))},
                        {"width", h.width},      {"height", h.height},
                        // The image file is as sent (a level of fewer rays smaller than the
                        // view); a viewer shows it scaled up to the view's size.
                        {"view_width", h.shownWidth()}, {"view_height", h.shownHeight()}, {"render_ms", h.renderMs},
                        {"encode_ms", h.encodeMs}, {"bytes", frames[i].messageBytes}, {"file", file}};
            row["error"] = h.error ? json{{"value", h.error->value}, {"method", h.error->method}} : json(nullptr);
            if (auto it = sentAt.find(h.request); it != sentAt.end()) {
                row["latency_ms"] = ms(receivedAt[i] - it->second);
                if (!h.final && receivedAt[i] <= lastInput + interval) interactiveLatency.push_back(row["latency_ms"]);
            }
            report.push_back(row);
        }
        json summary = {{"frames", frames.size()},
                        {"camera_messages", cameras.size()},
                        {"final_received", final},
                        {"interactive_latency_ms", {{"p50", percentile(interactiveLatency, 0.5)},
                                                    {"p95", percentile(interactiveLatency, 0.95)}}}};
        if (final) summary["last_input_to_final_ms"] = ms(receivedAt.back() - lastInput);
        std::ofstream(fs::path(outDir) / "report.json") << json{{"summary", summary}, {"frames", report}}.dump(2) << '\n';
        std::cout << summary.dump() << std::endl;
        return final ? 0 : 2;
    } catch (const std::exception &e) {
        std::cerr << "volcast-client: " << e.what() << std::endl;
        return 1;
    }
}
