//! The flags of `errmap_serve`'s settings.

use errmap_serve::Setting;
use std::any::Any;

/// The flag of a server setting.
pub fn words(setting: Setting) -> &'static str {
    match setting {
        Setting::TlsCert => "--tls-cert",
        Setting::TlsKey => "--tls-key",
        Setting::TrustedProxy => "--trusted-proxy",
        Setting::InsecureHttp => "--insecure-http",
        Setting::Role => "--role",
        Setting::Users => "--users",
        Setting::PasswordStdin => "--password-stdin",
        Setting::Replace => "--replace",
        Setting::Live => "--live",
        Setting::Runs => "--runs",
        Setting::Db => "--db",
    }
}

/// [`words`] for a setting given as `&dyn Any`; `None` when it is not a server setting.
pub fn flag(setting: &dyn Any) -> Option<&'static str> {
    setting.downcast_ref::<Setting>().map(|s| words(*s))
}
