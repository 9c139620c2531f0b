//! The KDE against KDEpy golden numbers and by its properties (one test binary).

mod golden;
mod properties;
