#pragma once
// Error estimates for frames, measured in the metric the client sees: RMSE over 8-bit RGB
// composited over black (the premultiplied colour, as JPEG frames show it), in [0, 1].
//
//  - Levels below the final: when a view's final frame is rendered, the frames of its
//    lower levels that were delivered for the same camera are compared with it, on the
//    background worker, as delivered: their JPEG decoded, so that the estimate includes the
//    coding error (near the final level it is most of the error: bonsai at 256², level 3
//    rendered 0.001 from the final frame and arrived 0.010 from it). Each level's estimate (per volume, transfer function, clip planes,
//    ladder and frame size) is the running mean of those measurements: method
//    "rmse_rgb8_vs_final". Until a view of that kind has reached its final frame: none.
//  - Every level below the final, once per kind of view: when a view of that kind first
//    reaches its final frame, each level is rendered in the background at the same camera
//    and size, JPEG-coded at its own quality, decoded and compared with the final frame: the
//    first measurement of every level, so that the ladder's choice (quality_ladder.hpp) sees
//    the whole error-against-time front before any of those levels was shown. Each render's
//    time per predicted sample is kept as that level's background cost.
//  - The final level: compared, on the background worker, with the double-precision
//    reference integrator on a small image (kSide pixels on the long side) at the same
//    camera, within a time budget of one core; where the reference would take longer, with
//    the fast renderer at a quarter of the step instead. Methods
//    "rmse_rgb8_vs_reference_<side>px" and "rmse_rgb8_vs_quarter_step_<side>px".
//
// Nothing here runs on the render thread except copying a frame to 8-bit RGB.

#include "protocol/frame.hpp"
#include "renderer/common/frame_renderer.hpp"
#include "server/preprocess_worker.hpp"
#include "server/quality_ladder.hpp"

#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

namespace volcast::server {

// 8-bit RGB over black, row by row.
struct Rgb8 {
    int width = 0, height = 0;
    std::vector<uint8_t> rgb;
};
Rgb8 toRgb8(const Image &image);
// A delivered JPEG frame decoded to 8-bit RGB (TurboJPEG); throws std::runtime_error with its message.
Rgb8 decodeJpegRgb8(const std::vector<uint8_t> &jpeg);
// The image scaled to width × height as a client shows a frame smaller than its view:
// resizeBilinear's (between pixel centres, clamped at the edges); itself if the size is its own.
Rgb8 scaledRgb8(Rgb8 image, int width, int height);
// RMSE over the channels in [0, 1] units; throws std::invalid_argument for different sizes.
double rmseRgb8(const Rgb8 &a, const Rgb8 &b);

// What a calibration needs of a view; the key names everything the error depends on.
struct CalibrationView {
    std::string key;
    std::shared_ptr<FrameRenderer> renderer;   // also keeps the volume alive
    TransferFunction transferFunction;
    Camera camera;
    std::vector<ClipPlane> clipPlanes;
    std::vector<Level> ladder;
    int width = 0, height = 0;
};

class ErrorCalibrator {
  public:
    static constexpr int kSide = 32;                    // reference image, pixels on the long side
    static constexpr double kReferenceBudgetSeconds = 2; // of one core, then the quarter-step fallback
    static constexpr double kReferenceTolerance = 1e-3;  // per channel: below an 8-bit step (1/255)
    static constexpr size_t kMaxKeys = 256;              // remembered kinds of view before clearing
    static constexpr double kLevelsBudgetSeconds = 4;    // of the level renders of one kind of view

    // What is measured of each of a view's `levels` levels: the error (none if not measured)
    // and the background cost in ms per predicted sample (0 if not measured).
    struct LevelsMeasured {
        std::vector<std::optional<double>> errors;
        std::vector<double> backgroundMsPerSample;
    };
    LevelsMeasured levels(const std::string &key, size_t levels) const;

    static constexpr double kLevelsWaitSeconds = 60;     // for the render thread to be free of drags
    static constexpr double kPollSeconds = 0.02;

    // `dragging` says whether a session is dragging now. The level renders hold the renderer's
    // frame lock, at the worker's low priority: each waits until no one drags, so that an
    // interactive frame never waits behind one (on a loaded machine, a starved calibration
    // render held the lock for hundreds of ms).
    ErrorCalibrator(PreprocessWorker &worker, bool enabled, std::function<bool()> dragging = {})
        : worker_(worker), enabled_(enabled), dragging_(std::move(dragging)) {}

    // The estimate for a frame of `level` of a view with this key; nullopt until measured.
    std::optional<protocol::ErrorEstimate> estimate(const std::string &key, int level, bool final) const;
    // A view's final frame, with the lower levels delivered for the same camera (level, the
    // JPEG bytes sent).
    void finalRendered(std::shared_ptr<const CalibrationView> view,
                       std::vector<std::pair<int, std::vector<uint8_t>>> levels, Rgb8 final, uint64_t viewSerial);

  private:
    struct Measured {
        std::vector<double> sum;
        std::vector<int> count;
        std::optional<protocol::ErrorEstimate> final;
        std::vector<double> backgroundMsPerSample;
    };
    void record(const std::string &key, int level, double rmse, size_t levels);
    void calibrateFinal(const CalibrationView &view, const std::atomic<bool> &cancelled);
    void calibrateLevels(const CalibrationView &view, const Rgb8 &final, const std::atomic<bool> &cancelled);

    PreprocessWorker &worker_;
    bool enabled_;
    std::function<bool()> dragging_;
    mutable std::mutex mutex_;
    std::map<std::string, Measured> measured_;
};

} // namespace volcast::server
