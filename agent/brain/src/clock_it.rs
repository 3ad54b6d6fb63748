//! The clock's words in Italian: "sono le 3 e un quarto del pomeriggio", "è l'una e mezza", "martedì 2 dicembre".
//!
//! Italian puts the verb and the article in the time itself ("sono le 3", but "è l'una", "è mezzogiorno"), so
//! `time.spoken` is a whole clause here; a program says `"{time.spoken}."` after capitalising nothing, because
//! [`spoken_time`] starts with a capital already.

pub(crate) const WEEKDAYS: [&str; 7] = [
    "lunedì",
    "martedì",
    "mercoledì",
    "giovedì",
    "venerdì",
    "sabato",
    "domenica",
];

pub(crate) const MONTHS: [&str; 12] = [
    "gennaio",
    "febbraio",
    "marzo",
    "aprile",
    "maggio",
    "giugno",
    "luglio",
    "agosto",
    "settembre",
    "ottobre",
    "novembre",
    "dicembre",
];

/// The greeting for the hour: "Buongiorno" until the afternoon is over, "Buonasera" in the evening, "Salve" at
/// night.
pub(crate) fn greeting(hour: u32) -> &'static str {
    match hour {
        5..=17 => "Buongiorno",
        18..=21 => "Buonasera",
        _ => "Salve",
    }
}

/// The time as an Italian clause: "Sono le 3 e un quarto del pomeriggio", "È l'una meno 10 di notte",
/// "È mezzogiorno".
pub(crate) fn spoken_time(hour: u32, minute: u32) -> String {
    // From twenty to the hour, in steps of five, the time is told from the next hour: "le 4 meno 20"; any
    // other minute is counted on from the hour ("le 3 e 34 minuti").
    let (shown_hour, minutes) = if minute >= 40 && minute.is_multiple_of(5) {
        ((hour + 1) % 24, format!(" meno {}", minutes(60 - minute)))
    } else if minute == 0 {
        (hour, String::new())
    } else {
        (hour, format!(" e {}", minutes(minute)))
    };
    let clock = match shown_hour {
        0 => format!("È mezzanotte{minutes}"),
        12 => format!("È mezzogiorno{minutes}"),
        1 | 13 => format!("È l'una{minutes}"),
        h => format!("Sono le {}{minutes}", h % 12),
    };
    // Noon and midnight say the part of the day themselves.
    if matches!(shown_hour, 0 | 12) {
        return clock;
    }
    let part = match hour {
        5..=11 => "di mattina",
        12..=17 => "del pomeriggio",
        18..=21 => "di sera",
        _ => "di notte",
    };
    format!("{clock} {part}")
}

fn minutes(m: u32) -> String {
    match m {
        15 => "un quarto".to_owned(),
        30 => "mezza".to_owned(),
        1 => "1 minuto".to_owned(),
        m if m % 5 == 0 => m.to_string(),
        m => format!("{m} minuti"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn says_the_time_as_italians_do() {
        assert_eq!(spoken_time(15, 15), "Sono le 3 e un quarto del pomeriggio");
        assert_eq!(spoken_time(8, 30), "Sono le 8 e mezza di mattina");
        assert_eq!(spoken_time(20, 45), "Sono le 9 meno un quarto di sera");
        assert_eq!(spoken_time(9, 7), "Sono le 9 e 7 minuti di mattina");
        assert_eq!(spoken_time(13, 0), "È l'una del pomeriggio");
        assert_eq!(spoken_time(0, 50), "È l'una meno 10 di notte");
        assert_eq!(spoken_time(12, 0), "È mezzogiorno");
        assert_eq!(spoken_time(12, 20), "È mezzogiorno e 20");
        assert_eq!(spoken_time(23, 40), "È mezzanotte meno 20");
        assert_eq!(spoken_time(0, 0), "È mezzanotte");
        assert_eq!(spoken_time(10, 1), "Sono le 10 e 1 minuto di mattina");
        assert_eq!(spoken_time(15, 34), "Sono le 3 e 34 minuti del pomeriggio");
    }

    #[test]
    fn greets_by_the_part_of_the_day() {
        assert_eq!(greeting(9), "Buongiorno");
        assert_eq!(greeting(16), "Buongiorno");
        assert_eq!(greeting(19), "Buonasera");
        assert_eq!(greeting(2), "Salve");
    }
}
