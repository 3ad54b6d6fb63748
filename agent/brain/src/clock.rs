//! The wall clock as programs see it (`time.hhmm`, `time.spoken`, `date.weekday`, ...), computed from a Unix time
//! and a UTC offset handed in by the host, so that the engine never reads the system clock itself.

use serde::Serialize;

use crate::clock_it;
use crate::language::Language;
use crate::value::Value;

/// A local civil time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct WallClock {
    /// Milliseconds since the Unix epoch (UTC), kept for trace timestamps.
    pub unix_ms: i64,
    pub year: i64,
    /// 1 to 12.
    pub month: u32,
    /// 1 to 31.
    pub day: u32,
    /// 0 is Monday, 6 is Sunday.
    pub weekday: u32,
    pub hour: u32,
    pub minute: u32,
    pub second: u32,
    /// The language of the words the clock gives (`time.spoken`, `date.month`...).
    pub language: Language,
}

const WEEKDAYS: [&str; 7] = [
    "Monday",
    "Tuesday",
    "Wednesday",
    "Thursday",
    "Friday",
    "Saturday",
    "Sunday",
];
const MONTHS: [&str; 12] = [
    "January",
    "February",
    "March",
    "April",
    "May",
    "June",
    "July",
    "August",
    "September",
    "October",
    "November",
    "December",
];

/// The clock fields a program may read, for the checker's error messages.
pub(crate) const FIELDS: [&str; 12] = [
    "time.hhmm",
    "time.hour",
    "time.minute",
    "time.second",
    "time.daypart",
    "time.greeting",
    "time.spoken",
    "date.weekday",
    "date.day",
    "date.month",
    "date.year",
    "date.spoken",
];

impl WallClock {
    /// The local time `utc_offset_s` seconds east of UTC at `unix_ms`.
    pub fn from_unix_ms(unix_ms: i64, utc_offset_s: i32) -> Self {
        let local_s = unix_ms.div_euclid(1000) + i64::from(utc_offset_s);
        let days = local_s.div_euclid(86_400);
        let second_of_day = local_s.rem_euclid(86_400);
        let (year, month, day) = civil_date(days);
        WallClock {
            unix_ms,
            year,
            month,
            day,
            // The epoch, 1970-01-01, was a Thursday (index 3 counting from Monday).
            weekday: (days + 3).rem_euclid(7) as u32,
            hour: (second_of_day / 3600) as u32,
            minute: (second_of_day / 60 % 60) as u32,
            second: (second_of_day % 60) as u32,
            language: Language::En,
        }
    }

    /// The same time, told in `language`.
    pub fn in_language(self, language: Language) -> Self {
        Self { language, ..self }
    }

    fn weekday_name(&self) -> &'static str {
        let i = self.weekday as usize % 7;
        match self.language {
            Language::En => WEEKDAYS[i],
            Language::It => clock_it::WEEKDAYS[i],
        }
    }

    fn month_name(&self) -> &'static str {
        let i = (self.month as usize + 11) % 12;
        match self.language {
            Language::En => MONTHS[i],
            Language::It => clock_it::MONTHS[i],
        }
    }

    /// Reads a dotted field such as `time.spoken`; `None` for an unknown field.
    pub fn field(&self, path: &[String]) -> Option<Value> {
        let path: Vec<&str> = path.iter().map(String::as_str).collect();
        Some(match path.as_slice() {
            ["time", "hhmm"] => Value::Text(format!("{:02}:{:02}", self.hour, self.minute)),
            ["time", "hour"] => Value::from(self.hour),
            ["time", "minute"] => Value::from(self.minute),
            ["time", "second"] => Value::from(self.second),
            ["time", "daypart"] => Value::from(self.daypart()),
            ["time", "greeting"] => Value::from(match self.language {
                Language::En => self.greeting(),
                Language::It => clock_it::greeting(self.hour),
            }),
            ["time", "spoken"] => Value::Text(match self.language {
                Language::En => self.spoken_time(),
                Language::It => clock_it::spoken_time(self.hour, self.minute),
            }),
            ["date", "weekday"] => Value::from(self.weekday_name()),
            ["date", "day"] => Value::from(self.day),
            ["date", "month"] => Value::from(self.month_name()),
            ["date", "year"] => Value::Num(self.year as f64),
            ["date", "spoken"] => Value::Text(format!(
                "{} {} {}",
                self.weekday_name(),
                self.day,
                self.month_name()
            )),
            _ => return None,
        })
    }

    fn daypart(&self) -> &'static str {
        match self.hour {
            5..=11 => "morning",
            12..=17 => "afternoon",
            18..=21 => "evening",
            _ => "night",
        }
    }

    fn greeting(&self) -> &'static str {
        match self.daypart() {
            "morning" => "Good morning",
            "afternoon" => "Good afternoon",
            "evening" => "Good evening",
            _ => "Hello",
        }
    }

    /// The time the way a person says it: "quarter past 3 in the afternoon", "noon", "7 minutes to 9 at night".
    fn spoken_time(&self) -> String {
        let (minute, hour) = (self.minute, self.hour);
        if minute == 0 && hour == 12 {
            return "noon".into();
        }
        if minute == 0 && hour == 0 {
            return "midnight".into();
        }
        let twelve = |h: u32| if h.is_multiple_of(12) { 12 } else { h % 12 };
        let minutes = |m: u32| match m {
            15 => "quarter".to_owned(),
            30 => "half".to_owned(),
            1 => "1 minute".to_owned(),
            m if m % 5 == 0 => m.to_string(),
            m => format!("{m} minutes"),
        };
        let clock = match minute {
            0 => format!("{} o'clock", twelve(hour)),
            1..=30 => format!("{} past {}", minutes(minute), twelve(hour)),
            _ => format!("{} to {}", minutes(60 - minute), twelve(hour + 1)),
        };
        let part = match hour {
            5..=11 => "in the morning",
            12..=17 => "in the afternoon",
            18..=21 => "in the evening",
            _ => "at night",
        };
        format!("{clock} {part}")
    }
}

/// Converts days since 1970-01-01 to a proleptic Gregorian (year, month, day), counting in 400-year eras whose
/// years start on 1 March so that the leap day falls at the end of a year.
fn civil_date(days: i64) -> (i64, u32, u32) {
    let shifted = days + 719_468; // days from 0000-03-01 to 1970-01-01
    let era = shifted.div_euclid(146_097);
    let day_of_era = shifted.rem_euclid(146_097);
    let year_of_era =
        (day_of_era - day_of_era / 1460 + day_of_era / 36_524 - day_of_era / 146_096) / 365;
    let day_of_year = day_of_era - (365 * year_of_era + year_of_era / 4 - year_of_era / 100);
    let month_from_march = (5 * day_of_year + 2) / 153;
    let day = (day_of_year - (153 * month_from_march + 2) / 5 + 1) as u32;
    let month = if month_from_march < 10 {
        month_from_march + 3
    } else {
        month_from_march - 9
    } as u32;
    let year = year_of_era + era * 400 + i64::from(month <= 2);
    (year, month, day)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn converts_known_dates() {
        // 2024-02-29 12:34:56 UTC, a Thursday.
        let clock = WallClock::from_unix_ms(1_709_210_096_000, 0);
        assert_eq!((clock.year, clock.month, clock.day), (2024, 2, 29));
        assert_eq!((clock.hour, clock.minute, clock.second), (12, 34, 56));
        assert_eq!(clock.weekday, 3);
        // One hour east of UTC.
        let clock = WallClock::from_unix_ms(1_709_210_096_000, 3600);
        assert_eq!(clock.hour, 13);
        // The epoch itself, and a day before it.
        assert_eq!(civil_date(0), (1970, 1, 1));
        assert_eq!(civil_date(-1), (1969, 12, 31));
        assert_eq!(civil_date(11_016), (2000, 2, 29));
    }

    fn spoken(hour: u32, minute: u32) -> String {
        let unix_ms = (i64::from(hour) * 3600 + i64::from(minute) * 60) * 1000;
        WallClock::from_unix_ms(unix_ms, 0).spoken_time()
    }

    #[test]
    fn speaks_the_time_naturally() {
        assert_eq!(spoken(15, 15), "quarter past 3 in the afternoon");
        assert_eq!(spoken(8, 30), "half past 8 in the morning");
        assert_eq!(spoken(20, 45), "quarter to 9 in the evening");
        assert_eq!(spoken(9, 7), "7 minutes past 9 in the morning");
        assert_eq!(spoken(23, 50), "10 to 12 at night");
        assert_eq!(spoken(11, 45), "quarter to 12 in the morning");
        assert_eq!(spoken(11, 0), "11 o'clock in the morning");
        assert_eq!(spoken(12, 0), "noon");
        assert_eq!(spoken(0, 0), "midnight");
    }

    #[test]
    fn reads_fields() {
        let clock = WallClock::from_unix_ms(1_709_210_096_000, 0);
        let field = |a: &str, b: &str| clock.field(&[a.to_owned(), b.to_owned()]);
        assert_eq!(field("time", "hhmm"), Some(Value::from("12:34")));
        assert_eq!(
            field("date", "spoken"),
            Some(Value::from("Thursday 29 February"))
        );
        assert_eq!(
            field("time", "greeting"),
            Some(Value::from("Good afternoon"))
        );
        assert_eq!(field("time", "nope"), None);
        let italian = clock.in_language(Language::It);
        let field = |a: &str, b: &str| italian.field(&[a.to_owned(), b.to_owned()]);
        assert_eq!(
            field("date", "spoken"),
            Some(Value::from("giovedì 29 febbraio"))
        );
        assert_eq!(field("time", "greeting"), Some(Value::from("Buongiorno")));
        assert_eq!(
            field("time", "spoken"),
            Some(Value::from("È mezzogiorno e 34 minuti"))
        );
    }
}
