// Scene JSON text (parseScene): what volcast-render reads from a file and what the server
// assembles from client messages. Invariants: only SceneError escapes, its message is valid
// UTF-8 (the server forwards such messages to clients inside JSON); an accepted scene
// written out (sceneToJson) parses back to an equal scene.

#include "fuzz/fuzz_check.hpp"
#include "renderer/model/scene.hpp"

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

using namespace volcast;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    const std::string_view text(reinterpret_cast<const char *>(data), size);
    Scene scene;
    try {
        scene = parseScene(text);
    } catch (const SceneError &e) {
        fuzz::check(fuzz::isValidUtf8(e.what()), "a scene error message is not valid UTF-8", e.what());
        return 0;
    }
    const std::string written = sceneToJson(scene);
    fuzz::check(fuzz::isValidUtf8(written), "a written scene is not valid UTF-8");
    Scene back;
    try {
        back = parseScene(written);
    } catch (const SceneError &e) {
        fuzz::fail("a written scene does not parse", std::string(e.what()) + "\n  scene: " + written);
    }
    fuzz::check(back == scene, "a written scene parses back different", written);
    return 0;
}
