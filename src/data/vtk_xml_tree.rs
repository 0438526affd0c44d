//! The XML part of a VTK XML file as a small tree, read with quick-xml, for
//! [`super::vtk_xml`]. Only elements, attributes and the direct text of each element are kept
//! (text split by entity references or CDATA is joined); positions are byte offsets in the file.

use super::DataError;
use super::MAX_SAMPLES;
use quick_xml::events::{BytesStart, Event};
use std::path::Path;

/// One XML element with its attributes and direct text.
pub(crate) struct Element {
    pub name: String,
    pub attrs: Vec<(String, String)>,
    pub at: usize,
    pub text: Vec<u8>,
    pub text_at: usize,
    pub children: Vec<usize>,
}

/// The XML part of the file as a tree (element 0 is the root).
pub(crate) struct Doc<'a> {
    pub path: &'a Path,
    pub elems: Vec<Element>,
}

/// A reference to one element of a [`Doc`].
#[derive(Clone, Copy)]
pub(crate) struct El<'d, 'a> {
    pub doc: &'d Doc<'a>,
    pub i: usize,
}

impl<'d, 'a> El<'d, 'a> {
    pub(crate) fn e(&self) -> &'d Element {
        &self.doc.elems[self.i]
    }

    pub(crate) fn name(&self) -> &'d str {
        &self.e().name
    }

    pub(crate) fn at(&self) -> usize {
        self.e().at
    }

    pub(crate) fn attr(&self, key: &str) -> Option<&'d str> {
        self.e()
            .attrs
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    pub(crate) fn children(&self) -> impl Iterator<Item = El<'d, 'a>> + 'd {
        let doc = self.doc;
        self.e().children.iter().map(move |&i| El { doc, i })
    }

    pub(crate) fn child(&self, name: &str) -> Option<El<'d, 'a>> {
        self.children().find(|c| c.name() == name)
    }

    pub(crate) fn format(
        &self,
        expected: impl Into<String>,
        found: impl Into<String>,
    ) -> DataError {
        DataError::Format {
            path: self.doc.path.to_path_buf(),
            location: format!("byte {} (<{}>)", self.at(), self.name()),
            expected: expected.into(),
            found: found.into(),
        }
    }

    pub(crate) fn unsupported(&self, what: impl Into<String>) -> DataError {
        DataError::Unsupported {
            path: self.doc.path.to_path_buf(),
            location: format!("byte {} (<{}>)", self.at(), self.name()),
            what: what.into(),
        }
    }

    /// A required child element.
    pub(crate) fn need(&self, name: &str) -> Result<El<'d, 'a>, DataError> {
        self.child(name)
            .ok_or_else(|| self.format(format!("a <{name}> element"), "none"))
    }

    /// A required attribute.
    pub(crate) fn need_attr(&self, key: &str) -> Result<&'d str, DataError> {
        self.attr(key)
            .ok_or_else(|| self.format(format!("a {key}=\"...\" attribute"), "none"))
    }

    /// An attribute of whitespace-separated numbers, exactly `n` of them.
    pub(crate) fn numbers<T: std::str::FromStr>(
        &self,
        key: &str,
        n: usize,
    ) -> Result<Option<Vec<T>>, DataError> {
        let Some(text) = self.attr(key) else {
            return Ok(None);
        };
        let values: Option<Vec<T>> = text
            .split_ascii_whitespace()
            .map(|t| t.parse().ok())
            .collect();
        match values {
            Some(v) if v.len() == n => Ok(Some(v)),
            _ => Err(self.format(format!("{key} with {n} numbers"), format!("\"{text}\""))),
        }
    }

    /// A count attribute, checked against [`MAX_SAMPLES`].
    pub(crate) fn count(&self, key: &str) -> Result<u64, DataError> {
        let text = self.need_attr(key)?;
        match text.trim().parse::<u64>() {
            Ok(n) if n <= MAX_SAMPLES => Ok(n),
            Ok(n) => Err(self.format(format!("{key} at most {MAX_SAMPLES}"), n.to_string())),
            Err(_) => Err(self.format(format!("{key} as a whole number"), format!("\"{text}\""))),
        }
    }
}

/// Reads the XML part of `bytes` into a tree; `appended` says whether the document was cut at
/// `<AppendedData` (then its open elements are closed silently).
pub(crate) fn build<'a>(
    path: &'a Path,
    xml: &'a [u8],
    appended: bool,
) -> Result<Doc<'a>, DataError> {
    let xml_error = |at: u64, found: String| DataError::Format {
        path: path.to_path_buf(),
        location: format!("byte {at}"),
        expected: "well-formed XML".into(),
        found,
    };
    let text = std::str::from_utf8(xml)
        .map_err(|e| xml_error(e.valid_up_to() as u64, "invalid UTF-8".into()))?;
    let mut reader = quick_xml::Reader::from_str(text);
    let mut doc = Doc {
        path,
        elems: Vec::new(),
    };
    let mut stack: Vec<usize> = Vec::new();
    loop {
        let at = reader.buffer_position() as usize;
        let event = reader
            .read_event()
            .map_err(|e| xml_error(reader.error_position(), e.to_string()))?;
        let push_text = |bytes: &[u8], doc: &mut Doc| {
            if let Some(&top) = stack.last() {
                let e = &mut doc.elems[top];
                if e.text.is_empty() {
                    e.text_at = at;
                }
                e.text.extend_from_slice(bytes);
            }
        };
        match event {
            Event::Start(e) => {
                let i = new_element(&mut doc, &stack, &e, at, &reader)?;
                stack.push(i);
            }
            Event::Empty(e) => {
                new_element(&mut doc, &stack, &e, at, &reader)?;
            }
            Event::End(_) => {
                stack.pop();
            }
            Event::Text(t) => push_text(&t, &mut doc),
            Event::CData(t) => push_text(&t, &mut doc),
            Event::GeneralRef(r) => push_text(&[&b"&"[..], &r, &b";"[..]].concat(), &mut doc),
            Event::Eof => break,
            Event::Comment(_) | Event::Decl(_) | Event::PI(_) | Event::DocType(_) => {}
        }
    }
    if doc.elems.is_empty() || (!stack.is_empty() && !appended) {
        return Err(xml_error(
            xml.len() as u64,
            "end of file before the closing </VTKFile>".into(),
        ));
    }
    Ok(doc)
}

fn new_element<'a>(
    doc: &mut Doc<'a>,
    stack: &[usize],
    e: &BytesStart,
    at: usize,
    reader: &quick_xml::Reader<&[u8]>,
) -> Result<usize, DataError> {
    let mut attrs = Vec::new();
    for a in e.attributes() {
        let a = a.map_err(|err| DataError::Format {
            path: doc.path.to_path_buf(),
            location: format!("byte {at}"),
            expected: "well-formed XML attributes".into(),
            found: err.to_string(),
        })?;
        let value = a
            .decode_and_unescape_value(reader.decoder())
            .map_err(|err| DataError::Format {
                path: doc.path.to_path_buf(),
                location: format!("byte {at}"),
                expected: "a well-formed attribute value".into(),
                found: err.to_string(),
            })?;
        attrs.push((
            String::from_utf8_lossy(a.key.as_ref()).into_owned(),
            value.into_owned(),
        ));
    }
    let i = doc.elems.len();
    doc.elems.push(Element {
        name: String::from_utf8_lossy(e.name().as_ref()).into_owned(),
        attrs,
        at,
        text: Vec::new(),
        text_at: at,
        children: Vec::new(),
    });
    if let Some(&parent) = stack.last() {
        doc.elems[parent].children.push(i);
    } else if i != 0 {
        return Err(DataError::Format {
            path: doc.path.to_path_buf(),
            location: format!("byte {at}"),
            expected: "a single root element".into(),
            found: format!("a second one, <{}>", doc.elems[i].name),
        });
    }
    Ok(i)
}
