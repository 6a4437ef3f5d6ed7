#pragma once
// Everything of volcast::protocol in one include.

#include "protocol/client_messages.hpp"
#include "protocol/errors.hpp"
#include "protocol/frame.hpp"
#include "protocol/server_messages.hpp"
#include "protocol/slice.hpp"
#include "protocol/utf8.hpp"
#include "protocol/version.hpp"
#include "protocol/volume_name.hpp"
