//! Who a face is: dlib's 128-number descriptor, and matching it against the people the agent was introduced to.

/// Two descriptors of one person lie closer than this (dlib's threshold: 99.38% on Labeled Faces in the Wild).
pub const SAME_PERSON_DISTANCE: f32 = 0.6;

/// A face's descriptor.
#[derive(Debug, Clone, PartialEq)]
pub struct Descriptor(pub [f32; 128]);

impl Descriptor {
    /// Euclidean distance.
    pub fn distance(&self, other: &Descriptor) -> f32 {
        self.0
            .iter()
            .zip(&other.0)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f32>()
            .sqrt()
    }

    /// The numbers, for storing.
    pub fn to_vec(&self) -> Vec<f32> {
        self.0.to_vec()
    }

    /// Back from stored numbers; `None` unless there are 128 finite ones.
    pub fn from_slice(values: &[f32]) -> Option<Descriptor> {
        let array: [f32; 128] = values.try_into().ok()?;
        array
            .iter()
            .all(|v| v.is_finite())
            .then_some(Descriptor(array))
    }
}

/// A person the agent knows, by the name they gave.
#[derive(Debug, Clone, PartialEq)]
pub struct Acquaintance {
    pub name: String,
    pub descriptor: Descriptor,
}

/// The nearest acquaintance within `threshold` of `face`, and its distance.
pub fn recognise<'a>(
    face: &Descriptor,
    known: &'a [Acquaintance],
    threshold: f32,
) -> Option<(&'a Acquaintance, f32)> {
    known
        .iter()
        .map(|person| (person, person.descriptor.distance(face)))
        .filter(|(_, distance)| *distance < threshold)
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(value: f32) -> Descriptor {
        let mut d = [0f32; 128];
        d[0] = value;
        Descriptor(d)
    }

    #[test]
    fn the_nearest_acquaintance_within_the_threshold_is_recognised() {
        let known = vec![
            Acquaintance {
                name: "Anna".into(),
                descriptor: at(0.0),
            },
            Acquaintance {
                name: "Bruno".into(),
                descriptor: at(0.5),
            },
        ];
        let found = recognise(&at(0.4), &known, SAME_PERSON_DISTANCE);
        assert_eq!(found.map(|(p, _)| p.name.as_str()), Some("Bruno"));
        assert!(recognise(&at(2.0), &known, SAME_PERSON_DISTANCE).is_none());
        assert!(recognise(&at(0.0), &[], SAME_PERSON_DISTANCE).is_none());
    }

    #[test]
    fn stored_numbers_come_back_only_whole_and_finite() {
        let d = at(0.25);
        assert_eq!(Descriptor::from_slice(&d.to_vec()), Some(d));
        assert_eq!(Descriptor::from_slice(&[0.0; 127]), None);
        let mut bad = vec![0.0; 128];
        bad[3] = f32::NAN;
        assert_eq!(Descriptor::from_slice(&bad), None);
    }
}
