// deformbench core, not part of the SDK: whether this build runs under AddressSanitizer, for the
// few places that behave differently there (the plugin loader keeps plugins mapped; tests that
// need a child to die by a signal skip). DEFORM_ASAN is 1 under gcc's __SANITIZE_ADDRESS__ or
// clang's __has_feature(address_sanitizer), else 0.
#pragma once

#if defined(__SANITIZE_ADDRESS__)
#define DEFORM_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define DEFORM_ASAN 1
#endif
#endif
#ifndef DEFORM_ASAN
#define DEFORM_ASAN 0
#endif
